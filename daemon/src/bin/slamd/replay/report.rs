//! What `slamd replay` prints, for either dimension: the latency, the
//! engine's counters, the final χ² and ATE, the sampled prefixes and the
//! loop closures switched off.

use super::{Latency, Outcome, ReplayOpts};
use crate::robust::Rejected;
use crate::solve::file_name;
use slamd::engine::EngineStats;
use slamd::graph::{chi2, EdgeCost, PoseGraph};

/// A replay's figures.
pub struct Report {
    pub mode: &'static str,
    pub keyframes: usize,
    pub edges: usize,
    pub latency: Latency,
    pub total_s: f64,
    pub closing_s: f64,
    pub resolves: usize,
    pub engine: Option<EngineStats>,
    /// Percentiles of the outlier filter's decision lags, in keyframes.
    pub decisions: Latency,
    pub chi2: f64,
    pub ate: Option<f64>,
    pub checked: usize,
    pub ratios: Vec<(usize, f64)>,
    pub robust: Rejected,
    pub switched: bool,
    /// How many snapshots each edge weighed in (switch ≥ 0.5), in file
    /// order (embedded only).
    pub weighted: Option<Vec<u32>>,
}

impl Report {
    /// The figures of `out` on `graph`; `ate` scores the final poses and
    /// `optimum` gives a prefix's batch optimum.
    pub fn of<P: EdgeCost>(
        graph: &PoseGraph<P>,
        out: Outcome<P>,
        mode: &'static str,
        engine: Option<EngineStats>,
        ate: Option<f64>,
        optimum: impl Fn(&PoseGraph<P>) -> anyhow::Result<f64>,
    ) -> anyhow::Result<Report> {
        let ratios = out
            .checked
            .iter()
            .map(|(k, poses)| {
                let prefix = graph.prefix(k + 1);
                let best = optimum(&prefix)?;
                Ok((k + 1, chi2(&prefix, poses) / best.max(f64::MIN_POSITIVE)))
            })
            .collect::<anyhow::Result<Vec<(usize, f64)>>>()?;
        Ok(Report {
            mode,
            keyframes: graph.len(),
            edges: graph.edges().len(),
            total_s: out.total_s,
            closing_s: out.closing_s,
            resolves: out.resolves,
            engine,
            chi2: chi2(graph, &out.poses),
            ate,
            checked: out.checked.len(),
            ratios,
            robust: Rejected::of(graph, out.switches.as_deref()),
            switched: out.switches.is_some(),
            latency: Latency::of(out.latencies),
            decisions: Latency::of(out.decision_lags),
            weighted: out.weighted,
        })
    }

    fn worst_ratio(&self) -> Option<f64> {
        self.ratios.iter().map(|&(_, r)| r).reduce(f64::max)
    }

    /// The JSON object's fields, `extra` added.
    pub fn json(
        &self,
        opts: &ReplayOpts,
        skipped: serde_json::Value,
        extra: serde_json::Value,
    ) -> serde_json::Value {
        let mut v = serde_json::json!({
            "file": opts.file.display().to_string(),
            "skipped_lines": skipped,
            "mode": self.mode,
            "keyframes": self.keyframes,
            "edges": self.edges,
            "p50_us": self.latency.p50,
            "p99_us": self.latency.p99,
            "max_us": self.latency.max,
            "total_s": self.total_s,
            "closing_s": self.closing_s,
            "resolves": self.resolves,
            "engine": self.engine.map(|s| serde_json::json!({
                "refreshes": s.refreshes,
                "relinearisations": s.relinearisations,
                "reorders": s.reorders,
                "nonlinear_resolves": s.nonlinear_resolves,
                "drift_resolves": s.drift_resolves,
                "recoveries": s.recoveries,
                "walked_entries": s.work.walked,
                "solved_entries": s.work.solved,
                "pending": s.pending,
                "decision_lag_keyframes": ([self.decisions.p50, self.decisions.p99, self.decisions.max].map(|k| k as u64)),
            })),
            "chi2": self.chi2,
            "ate": self.ate,
            "prefixes_checked": self.checked,
            "worst_prefix_ratio": self.worst_ratio(),
            "prefix_ratios": self.ratios,
            "loop_closures": self.robust.loop_closures,
            "switched_off": self.robust.rejected.len(),
            "rejected_edges": self.switched.then_some(&self.robust.rejected),
            "weighted_snapshots": self.weighted,
        });
        if let (Some(v), serde_json::Value::Object(extra)) = (v.as_object_mut(), extra) {
            v.extend(extra);
        }
        v
    }

    /// The text report; `more` prints lines of its own after the ATE.
    pub fn print(&self, opts: &ReplayOpts, label: &str, more: impl FnOnce()) {
        println!(
            "{} ({label}): {} keyframes, {} edges",
            file_name(&opts.file),
            self.keyframes,
            self.edges
        );
        let lat = &self.latency;
        println!(
            "latency per keyframe  p50 {:.0} µs  p99 {:.0} µs  max {:.0} µs",
            lat.p50, lat.p99, lat.max
        );
        println!(
            "total                 {:.3} s  ({} re-solves; closing one {:.3} s)",
            self.total_s, self.resolves, self.closing_s
        );
        println!("final chi2            {:.3}", self.chi2);
        if let Some(a) = self.ate {
            println!("ate                   {a:.4} m");
        }
        more();
        if self.switched {
            println!(
                "loop closures         {} ({} switched off)",
                self.robust.loop_closures,
                self.robust.rejected.len()
            );
        }
        if let Some(w) = self.worst_ratio() {
            println!(
                "worst snapshot/prefix-optimum chi2 over {} prefixes: {w:.4}",
                self.checked
            );
        }
    }
}
