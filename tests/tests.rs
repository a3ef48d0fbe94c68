//! slamd's integration tests, one target.

mod accuracy;
mod cli;
mod formulations;
mod incremental;
