//! The daemon and its frontends over shared memory.
//!
//! - [`serve`]: the daemon (`slamd run`). Its IPC thread blocks on the
//!   transport's WaitSet and forwards checked messages over a crossbeam
//!   channel; its engine thread applies each batch, publishes one snapshot
//!   per batch and a rejection per refused message.
//! - [`Frontend`] (from [`slamd_protocol`]): what a frontend publishes
//!   with: numbered keyframes and edges, then a poke.
//!
//! No iceoryx2 type appears here; the ports live in
//! [`slamd_protocol::transport`].

mod acks;
mod durability;
mod durable;
pub(crate) mod engine_loop;
mod health;
mod held;
mod publication;
mod server;

pub use engine_loop::Counters;
pub use server::{serve, serve_map, serve_until, ServeError, Server};
pub use slamd_protocol::transport::{SnapshotLink as Snapshots, SwitchesSample, TransportError};
pub use slamd_protocol::{Endpoint, Frontend, MapSnapshot};
