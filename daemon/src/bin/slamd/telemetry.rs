//! Log setup: `tracing` to stderr, filtered by the configuration's `log`
//! (SLAMD_LOG overrides it through the configuration).

use std::sync::Once;

static INIT: Once = Once::new();

/// Installs the subscriber once; later calls do nothing.
pub fn init(filter: &str) {
    INIT.call_once(|| {
        let filter = tracing_subscriber::EnvFilter::try_new(filter)
            .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
        tracing_subscriber::fmt()
            .with_env_filter(filter)
            .with_writer(std::io::stderr)
            .init();
        slamd_protocol::transport::quiet_logs();
    });
}
