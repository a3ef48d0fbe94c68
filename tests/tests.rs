//! slamd's integration tests, one target.

mod accuracy;
mod cli;
mod corruption;
mod daemon;
mod durable;
mod edge_direction;
mod formulations;
mod fuzz;
mod gps;
mod gps3;
mod incremental;
mod judge;
mod marginals;
mod outliers;
mod restore;
mod spatial;
mod spatial_daemon;
mod true_loop_closures;
