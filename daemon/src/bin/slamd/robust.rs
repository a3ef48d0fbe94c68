//! Outlier-filter options shared by `solve` and `replay`, and the counts
//! both print.

use clap::Args;
use slamd::graph::{EdgeKind, PoseGraph, RigidMotion};
use slamd::outliers::{OutlierConfig, REJECTED_BELOW};
use slamd::robust::{Kernel, DEFAULT_PHI};

#[derive(Args, Debug, Clone)]
pub struct RobustOpts {
    /// The loop-closure switch: dcs[:PHI] (default Φ 16.27/3), sc[:XI]
    /// (default Ξ 1) or asc (paper B as printed).
    #[arg(long, value_parser = parse_kernel)]
    pub kernel: Option<Kernel>,
    /// Run paper A's cycle-consistency test before the kernel.
    #[arg(long)]
    pub cycles: bool,
    /// Keep only the largest set of loop closures that agree pairwise
    /// through the odometry before the kernel (PCM).
    #[arg(long)]
    pub pairwise: bool,
}

impl RobustOpts {
    /// `base` with the options applied.
    pub fn apply(&self, mut base: OutlierConfig) -> OutlierConfig {
        if let Some(k) = self.kernel {
            base.kernel = k;
        }
        base.cycles |= self.cycles;
        base.pairwise |= self.pairwise;
        base
    }
}

fn parse_kernel(s: &str) -> Result<Kernel, String> {
    let (name, value) = match s.split_once(':') {
        Some((n, v)) => {
            let v: f64 = v.parse().map_err(|_| format!("`{v}` is not a number"))?;
            (n, Some(v))
        }
        None => (s, None),
    };
    let kernel = match name {
        "dcs" => Kernel::Dcs {
            phi: value.unwrap_or(DEFAULT_PHI),
        },
        "sc" => Kernel::Sc {
            xi: value.unwrap_or(1.0),
        },
        "asc" if value.is_none() => Kernel::Asc,
        _ => return Err(format!("unknown kernel `{s}` (dcs[:PHI], sc[:XI], asc)")),
    };
    kernel.check().map_err(|m| format!("`{s}`: {m}"))?;
    Ok(kernel)
}

/// Loop closures and those the filter holds wrong, in file order.
pub struct Rejected {
    pub loop_closures: usize,
    /// Indices (file order of the edge lines) of the edges whose final
    /// switch is below 0.5.
    pub rejected: Vec<usize>,
}

impl Rejected {
    pub fn of<P: RigidMotion>(graph: &PoseGraph<P>, switches: Option<&[f64]>) -> Rejected {
        let loop_closures = graph
            .edges()
            .iter()
            .filter(|e| e.kind != EdgeKind::Odometry)
            .count();
        let rejected = switches.map_or_else(Vec::new, |s| {
            (0..s.len()).filter(|&e| s[e] < REJECTED_BELOW).collect()
        });
        Rejected {
            loop_closures,
            rejected,
        }
    }
}
