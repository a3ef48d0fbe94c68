//! `--gps FIXES.csv` for `solve` and `replay`: fixes into the local ENU
//! frame, keyed to the graph's keyframes.

use anyhow::Context;
use clap::Args;
use faer::c64;
use slamd::engine::FixInput;
use slamd::geometry::Pose2;
use slamd::gps::{Geodetic, Georef, GpsFix, GpsInput, LocalFrame};
use slamd::graph::PoseGraph;
use std::path::PathBuf;

#[derive(Args, Debug, Clone)]
pub struct GpsOpts {
    /// GPS fixes: keyframe,lat,lon,sigma_east,sigma_north[,true_east,true_north].
    #[arg(long)]
    pub gps: Option<PathBuf>,
    /// Origin of the local ENU frame, LAT,LON[,HEIGHT] (default: the first fix).
    #[arg(long, value_parser = Geodetic::parse)]
    pub gps_origin: Option<Geodetic>,
    /// Use only paper A's shape equations (no absolute positions, no georeference).
    #[arg(long)]
    pub gps_paper_only: bool,
}

/// Fixes ready for a solve, with what is needed to score them.
pub struct LoadedGps {
    pub input: GpsInput,
    /// The fixes as a frontend publishes them (keyframe ids, geodetic).
    pub wire: Vec<FixInput>,
    /// True ENU positions from the file, by keyframe index.
    pub truth: Vec<(usize, c64)>,
}

pub fn load(opts: &GpsOpts, graph: &PoseGraph) -> anyhow::Result<Option<LoadedGps>> {
    let Some(path) = &opts.gps else {
        return Ok(None);
    };
    let records = slamd::io::read_fixes(path)?;
    let first = records
        .first()
        .with_context(|| format!("{}: no fixes", path.display()))?;
    let frame = LocalFrame::new(opts.gps_origin.unwrap_or(first.position));
    let mut fixes = Vec::with_capacity(records.len());
    let mut truth = Vec::new();
    let mut wire = Vec::with_capacity(records.len());
    for r in &records {
        let k = graph.index_of(r.keyframe).with_context(|| {
            format!(
                "{}: fix for keyframe {} that the graph lacks",
                path.display(),
                r.keyframe
            )
        })?;
        let cov = [floor(r.sigma[0]).powi(2), 0.0, 0.0, floor(r.sigma[1]).powi(2)];
        let input = FixInput {
            keyframe: r.keyframe,
            position: r.position,
            covariance: cov,
            height_variance: None,
        };
        let position = GpsFix::checked_position(&input)?;
        fixes.push(GpsFix::at(&input, &position, k, &frame));
        wire.push(input);
        if let Some([te, tn]) = r.truth {
            truth.push((k, c64::new(te, tn)));
        }
    }
    let mut input = GpsInput::new(fixes);
    input.absolute = !opts.gps_paper_only;
    Ok(Some(LoadedGps { input, wire, truth }))
}

/// σ below which a file's fix counts as exact: `synth_gps.py --sigma 0`
/// writes 0, and a zero variance has no inverse.
pub const SIGMA_FLOOR: f64 = 1e-4;

fn floor(sigma: f64) -> f64 {
    sigma.max(SIGMA_FLOOR)
}

/// RMSE of the georeferenced positions against the file's true ENU
/// positions, where it has them.
pub fn enu_rmse(gps: &LoadedGps, georef: Option<&Georef>, poses: &[Pose2]) -> Option<f64> {
    let g = georef?;
    rmse(&gps.truth, |k| Some(g.to_enu(&poses[k]).position()))
}

/// RMSE of `enu(k)` against the true positions; `None` without truth or
/// when a keyframe has no ENU position.
pub fn rmse(truth: &[(usize, c64)], enu: impl Fn(usize) -> Option<c64>) -> Option<f64> {
    if truth.is_empty() {
        return None;
    }
    let mut sq = 0.0;
    for (k, t) in truth {
        sq += (enu(*k)? - t).norm_sqr();
    }
    Some((sq / truth.len() as f64).sqrt())
}
