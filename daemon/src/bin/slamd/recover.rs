//! `slamd recover --state DIR`: keep every journal record that can be
//! verified after corruption, the damaged file kept aside.

use clap::Args;
use slamd::geometry::Pose2;
use slamd::graph::Pose3;
use slamd::store::recovery::{recover, Recovery};
use slamd::store::StoreError;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct RecoverOpts {
    /// The state directory (no daemon may be running on it).
    #[arg(long)]
    pub state: PathBuf,
}

pub fn run(opts: RecoverOpts) -> anyhow::Result<()> {
    let done = match recover::<Pose2>(&opts.state) {
        Err(StoreError::Dimension { .. }) => recover::<Pose3>(&opts.state)?,
        other => other?,
    };
    print!("{}", report(&done));
    Ok(())
}

/// What was kept, what was left out and where the old file lies.
fn report(r: &Recovery) -> String {
    let mut out = String::new();
    let Some(aside) = &r.moved_to else {
        out.push_str(&format!(
            "journal: {} records, nothing damaged; nothing changed\n",
            r.kept
        ));
        return out;
    };
    out.push_str(&format!(
        "journal: kept {} records; left out {} damaged stretch(es):\n",
        r.kept,
        r.damage.len()
    ));
    for d in &r.damage {
        out.push_str(&format!("  byte {}: {} bytes ({})\n", d.offset, d.len, d.reason));
    }
    for l in &r.lost {
        out.push_str(&format!(
            "  lost: frontend {} messages {}..={} (acknowledged, so no frontend sends them again by itself)\n",
            l.frontend, l.first, l.last
        ));
    }
    out.push_str(&format!("the journal as it was: {}\n", aside.display()));
    out
}
