//! [`Frontend`]: publishing keyframes, edges and GPS fixes to a running
//! daemon, riding out its restarts.
//!
//! Every message gets the next number. The frontend keeps each message
//! until the daemon acknowledges it (the daemon's acknowledgement of a
//! number covers every message up to it). Each daemon start has its own
//! instance number; when the frontend sees a new one it sends again every
//! message the new daemon has not acknowledged, and the daemon drops the
//! ones it already had. A send that finds the daemon gone (its queue full
//! past the backpressure timeout) waits for a daemon to come back, up to
//! the reconnect bound, then fails with [`TransportError::DaemonGone`].
//!
//! A daemon that is alive shows it: it publishes its status with every
//! snapshot and on every idle tick, also while it holds acknowledgements
//! (its journal cannot be written). A frontend waiting for an
//! acknowledgement, or for room in the daemon's queue, keeps waiting as
//! long as statuses come, and gives up only after its bound with none.

use crate::codec::{edge_out, gps_out, keyframe_out, Origin};
use crate::message::{Edge, GpsFix, Keyframe};
use crate::transport::{FrontendLink, TransportError};
use slamd_types::{EdgeInput, FixInput, KeyframeId, Pose2, RigidMotion};
use std::collections::VecDeque;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

/// Where a frontend connects: the daemon's namespace, how long a send that
/// finds the daemon's queue full retries, and how long it waits for a
/// daemon that went away to come back.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Endpoint {
    /// The daemon's namespace (`slamd run --namespace`).
    pub namespace: String,
    /// The send timeout on a full queue.
    pub backpressure: Duration,
    /// How long to wait for a daemon to come back.
    pub reconnect: Duration,
}

impl Endpoint {
    /// `namespace` with a 200 ms backpressure timeout and a 30 s
    /// reconnect bound.
    pub fn new(namespace: &str) -> Self {
        Self {
            namespace: namespace.into(),
            backpressure: Duration::from_millis(200),
            reconnect: Duration::from_secs(30),
        }
    }
}

/// Messages kept for sending again at most; past it the oldest are
/// forgotten (a daemon that never acknowledges this frontend).
const OUTBOX_LIMIT: usize = 1 << 20;

/// Messages between two looks at the acknowledgements, when the caller
/// does not flush.
const PRUNE_EVERY: usize = 1024;

/// Messages sent again between two pokes of the daemon.
const POKE_EVERY: usize = 256;

/// How often a frontend waiting for a daemon looks again.
const POLL: Duration = Duration::from_millis(10);

/// A frontend waiting for a daemon that is alive says why at most this
/// often (and first after this long).
pub const SAY_EVERY: Duration = Duration::from_secs(5);

/// A wait for an acknowledgement, as it stands at one look: what
/// [`Frontend::wait_acknowledged_with`] hands its caller between looks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Waiting<'a> {
    /// The daemon's namespace.
    pub namespace: &'a str,
    /// The message waited for.
    pub sequence: u64,
    /// How long the wait has lasted.
    pub waited: Duration,
    /// Whether the daemon's last status said it holds acknowledgements
    /// because its journal cannot be written.
    pub holding: bool,
    /// Whether to say why now: the wait has lasted [`SAY_EVERY`], and that
    /// long has passed since it was last said.
    pub say: bool,
}

impl std::fmt::Display for Waiting<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let why = if self.holding {
            "holds its acknowledgements: its journal cannot be written (a full disk?)".to_string()
        } else {
            format!("has not acknowledged message {} yet", self.sequence)
        };
        write!(
            f,
            "the daemon serving `{}` is alive but {why}; waiting ({:.0} s so far)",
            self.namespace,
            self.waited.as_secs_f64()
        )
    }
}

static NEXT: AtomicU32 = AtomicU32::new(1);

/// One message as sent.
#[derive(Clone, Copy, Debug)]
enum Outgoing {
    Keyframe(Keyframe),
    Edge(Edge),
    Gps(GpsFix),
}

/// A frontend's connection to a daemon of `P`'s dimension ([`Pose2`] in
/// the plane, the default; [`Pose3`](slamd_types::Pose3) in space): each
/// message gets the next number; the daemon acknowledges numbers and names
/// them in rejections.
pub struct Frontend<P: RigidMotion = Pose2> {
    link: FrontendLink,
    endpoint: Endpoint,
    id: u32,
    sequence: u64,
    /// Messages not yet acknowledged, oldest first.
    outbox: VecDeque<(u64, Outgoing)>,
    /// The daemon instance last heard from (0: none yet).
    instance: u64,
    /// The daemon's acknowledgement of this frontend.
    acked: u64,
    /// Sends again after a daemon restart.
    resent: u64,
    /// When the daemon last published a status (or the frontend
    /// connected).
    heard: Instant,
    /// Whether that status said it holds acknowledgements.
    holding: bool,
    dimension: PhantomData<P>,
}

impl<P: RigidMotion> Frontend<P> {
    /// Connects to the daemon at `endpoint` (for example a daemon's
    /// configuration: its namespace, backpressure and reconnect bound).
    pub fn connect(endpoint: impl Into<Endpoint>) -> Result<Self, TransportError> {
        let endpoint = endpoint.into();
        let link = FrontendLink::open(&endpoint.namespace, endpoint.backpressure)?;
        // nonzero and distinct across processes and connections
        let id = (std::process::id().wrapping_mul(2654435761) ^ NEXT.fetch_add(1, Ordering::Relaxed)).max(1);
        let status = link.latest_status()?;
        let instance = status.map_or(0, |a| a.instance);
        let holding = status.is_some_and(|a| a.journal_failing != 0);
        Ok(Self {
            link,
            endpoint,
            id,
            sequence: 0,
            outbox: VecDeque::new(),
            instance,
            acked: 0,
            resent: 0,
            heard: Instant::now(),
            holding,
            dimension: PhantomData,
        })
    }

    /// Connects to the daemon serving `namespace`.
    pub fn connect_to(namespace: &str, backpressure: Duration) -> Result<Self, TransportError> {
        Self::connect(Endpoint {
            backpressure,
            ..Endpoint::new(namespace)
        })
    }

    /// This frontend's id in acknowledgements and rejections.
    pub fn id(&self) -> u32 {
        self.id
    }

    /// The number of the last message sent.
    pub fn last_sequence(&self) -> u64 {
        self.sequence
    }

    /// The number through which the daemon has acknowledged every message.
    pub fn acknowledged(&self) -> u64 {
        self.acked
    }

    /// Messages kept until the daemon acknowledges them.
    pub fn unacknowledged(&self) -> usize {
        self.outbox.len()
    }

    /// Messages sent again to a restarted daemon so far.
    pub fn resent(&self) -> u64 {
        self.resent
    }

    /// How long since the daemon last showed it is alive (a status seen by
    /// [`Self::poll`], or the connection).
    pub fn silent_for(&self) -> Duration {
        self.heard.elapsed()
    }

    /// Whether the daemon's last status said it holds acknowledgements
    /// because its journal cannot be written (a full disk): it is alive
    /// and resumes when it can write.
    pub fn holding(&self) -> bool {
        self.holding
    }

    /// Publishes a keyframe, with its time (ns, the frontend's clock; 0:
    /// none) and an optional initial pose; returns its message number.
    pub fn add_keyframe(
        &mut self,
        id: KeyframeId,
        timestamp_ns: u64,
        guess: Option<P>,
    ) -> Result<u64, TransportError> {
        let o = self.next();
        self.send(Outgoing::Keyframe(keyframe_out(id, timestamp_ns, guess, o)))
    }

    /// Publishes an edge; returns its message number.
    pub fn add_edge(&mut self, edge: &EdgeInput<P>) -> Result<u64, TransportError> {
        let o = self.next();
        self.send(Outgoing::Edge(edge_out(edge, o)))
    }

    /// Publishes a GPS fix; returns its message number.
    pub fn add_gps(&mut self, fix: &FixInput) -> Result<u64, TransportError> {
        let o = self.next();
        self.send(Outgoing::Gps(gps_out(fix, o)))
    }

    /// Publishes a raw edge message as is (tests of hostile input).
    pub fn send_raw_edge(&mut self, mut m: Edge) -> Result<u64, TransportError> {
        let o = self.next();
        m.frontend = o.frontend;
        m.sequence = o.sequence;
        self.send(Outgoing::Edge(m))
    }

    /// Wakes the daemon to take everything published so far.
    pub fn flush(&mut self) -> Result<(), TransportError> {
        // one poke for what was sent again and what was sent: a second,
        // taken while the next keyframe is half published, would split it
        // over two batches
        self.refresh()?;
        self.link.poke()
    }

    /// Reads the daemon's latest acknowledgements: forgets what they
    /// cover and, if a new daemon is serving, sends it again whatever it
    /// has not acknowledged. Never blocks for long (a send may wait for
    /// backpressure).
    pub fn poll(&mut self) -> Result<(), TransportError> {
        if self.refresh()? {
            self.link.poke()?;
        }
        Ok(())
    }

    /// [`Self::poll`] without waking the daemon; whether anything was sent
    /// again.
    fn refresh(&mut self) -> Result<bool, TransportError> {
        let Some(a) = self.link.latest_status()? else {
            return Ok(false);
        };
        self.heard = Instant::now();
        self.holding = a.journal_failing != 0;
        let acked = a.ack_of(self.id).unwrap_or(0);
        self.forget_through(acked);
        if a.instance == self.instance {
            return Ok(false);
        }
        // also at the first status seen: a daemon that died before this
        // frontend heard from it got messages it never took; what the
        // same daemon already has is dropped there as a repeat
        self.instance = a.instance;
        self.acked = acked;
        self.send_again()?;
        Ok(!self.outbox.is_empty())
    }

    /// Waits until the daemon has acknowledged message `sequence`, riding
    /// out daemon restarts, for as long as the daemon shows it is alive:
    /// `false` only once `silence` has passed with no status from it (it is
    /// gone, or was never there). A daemon that holds acknowledgements
    /// (its journal cannot be written) is waited for; why is logged
    /// (`tracing`, warning) at most every [`SAY_EVERY`]. A message not yet
    /// sent is never acknowledged: `false` at once.
    pub fn wait_acknowledged(&mut self, sequence: u64, silence: Duration) -> Result<bool, TransportError> {
        self.wait_acknowledged_with(sequence, silence, |w| {
            if w.say {
                tracing::warn!("{w}");
            }
            true
        })
    }

    /// [`Self::wait_acknowledged`], calling `between` at every look (every
    /// 10 ms) with how the wait stands; `between` saying `false` ends the
    /// wait with `false` (an interrupt, or a caller's own bound on the
    /// whole wait), and it decides what to do with [`Waiting::say`].
    pub fn wait_acknowledged_with(
        &mut self,
        sequence: u64,
        silence: Duration,
        mut between: impl FnMut(&Waiting<'_>) -> bool,
    ) -> Result<bool, TransportError> {
        if sequence > self.sequence {
            return Ok(false);
        }
        let started = Instant::now();
        // a status seen before the wait began counts from the wait
        self.heard = self.heard.max(started);
        let mut said: Option<Instant> = None;
        loop {
            self.poll()?;
            if self.acked >= sequence {
                return Ok(true);
            }
            if self.silent_for() >= silence {
                return Ok(false);
            }
            let waited = started.elapsed();
            let say = waited >= SAY_EVERY && said.is_none_or(|t| t.elapsed() >= SAY_EVERY);
            if say {
                said = Some(Instant::now());
            }
            let w = Waiting {
                namespace: &self.endpoint.namespace,
                sequence,
                waited,
                holding: self.holding,
                say,
            };
            if !between(&w) {
                return Ok(false);
            }
            std::thread::sleep(POLL.min(silence.saturating_sub(self.silent_for())));
        }
    }

    fn next(&mut self) -> Origin {
        self.sequence += 1;
        Origin {
            frontend: self.id,
            sequence: self.sequence,
        }
    }

    fn forget_through(&mut self, acked: u64) {
        self.acked = self.acked.max(acked);
        while self.outbox.front().is_some_and(|(s, _)| *s <= acked) {
            self.outbox.pop_front();
        }
    }

    /// Keeps `m` until acknowledged and publishes it; a daemon gone means
    /// waiting for the next one.
    fn send(&mut self, m: Outgoing) -> Result<u64, TransportError> {
        let sequence = self.sequence;
        if self.outbox.len() == OUTBOX_LIMIT {
            self.outbox.pop_front();
        }
        self.outbox.push_back((sequence, m));
        if self.outbox.len().is_multiple_of(PRUNE_EVERY) {
            // between flushes, still forget what was acknowledged
            let before = self.instance;
            self.poll()?;
            if self.instance != before {
                // sent again with the rest
                return Ok(sequence);
            }
        }
        match self.publish(&m) {
            Ok(()) => Ok(sequence),
            Err(TransportError::Backpressure { .. }) => {
                self.await_daemon()?;
                Ok(sequence)
            }
            Err(e) => Err(e),
        }
    }

    fn publish(&self, m: &Outgoing) -> Result<(), TransportError> {
        match *m {
            Outgoing::Keyframe(k) => self.link.send_keyframe(k),
            Outgoing::Edge(e) => self.link.send_edge(e),
            Outgoing::Gps(g) => self.link.send_gps(g),
        }
    }

    /// Sends every kept message again, oldest first, waking the daemon
    /// every [`POKE_EVERY`] (more than its queues hold may be kept); the
    /// caller wakes it for the rest.
    fn send_again(&mut self) -> Result<(), TransportError> {
        let started = Instant::now();
        for i in 0..self.outbox.len() {
            let m = self.outbox[i].1;
            loop {
                match self.publish(&m) {
                    Ok(()) => break,
                    Err(TransportError::Backpressure { .. })
                        if started.elapsed() < self.endpoint.reconnect =>
                    {
                        self.link.poke()?;
                    }
                    Err(TransportError::Backpressure { .. }) => {
                        return Err(TransportError::DaemonGone {
                            namespace: self.endpoint.namespace.clone(),
                            waited_s: started.elapsed().as_secs_f64(),
                        })
                    }
                    Err(e) => return Err(e),
                }
            }
            self.resent += 1;
            if i % POKE_EVERY == POKE_EVERY - 1 {
                self.link.poke()?;
            }
        }
        Ok(())
    }

    /// The daemon's queue stayed full: it is gone, stuck or holding. Waits
    /// for a new daemon (then everything kept went to it) or for the queue
    /// to take the newest message, for the reconnect bound and then as
    /// long as the daemon keeps publishing statuses.
    fn await_daemon(&mut self) -> Result<(), TransportError> {
        let started = Instant::now();
        let before = self.instance;
        let _ = self.link.poke();
        let reconnect = self.endpoint.reconnect;
        while started.elapsed() < reconnect || self.silent_for() < reconnect {
            std::thread::sleep(POLL);
            self.poll()?;
            if self.instance != before {
                return Ok(());
            }
            let newest = self.outbox.back().map(|(_, m)| *m);
            match newest.map(|m| self.publish(&m)) {
                Some(Ok(())) | None => return Ok(()),
                Some(Err(TransportError::Backpressure { .. })) => {}
                Some(Err(e)) => return Err(e),
            }
        }
        Err(TransportError::DaemonGone {
            namespace: self.endpoint.namespace.clone(),
            waited_s: started.elapsed().as_secs_f64(),
        })
    }
}
