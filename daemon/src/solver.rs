//! The batch pipeline: a linear formulation, then optionally the polish.

use crate::geometry::Pose2;
use crate::gps::{variance_factor, Georef, GpsInput};
use crate::graph::{chi2, Edge, EdgeKind, GraphError, Pose3, PoseGraph};
use crate::linear::{chordal, two_stage, virtual_frame, Pivot};
use crate::nonlinear::{polish, LevenbergMarquardtParams, LiePose, LmReport, Problem};
use crate::outliers::consistency::ConsistencyGraph;
use crate::outliers::{cycles, robust_polish, Comparison, OutlierConfig, RobustEdges};
use crate::robust::Kernel;
use crate::sparse::FactorError;
use std::fmt;
use std::str::FromStr;
use std::time::Instant;

/// How the initial (linear) solution is computed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Formulation {
    /// Axes, then positions (docs/design.md, "Formulations"). The default.
    #[default]
    TwoStage,
    /// Paper A as printed: virtual frames, pivot on the neighbour.
    VirtualFrame,
    /// Paper A's triangles pivoted on `i_x`.
    VirtualFramePivot,
    /// Odometry composed along a spanning tree (the classic guess).
    Odometry,
}

impl Formulation {
    /// Every formulation, for tables and tests.
    pub const ALL: [Formulation; 4] = [
        Formulation::TwoStage,
        Formulation::VirtualFrame,
        Formulation::VirtualFramePivot,
        Formulation::Odometry,
    ];

    /// The command-line name.
    pub fn name(&self) -> &'static str {
        match self {
            Formulation::TwoStage => "two-stage",
            Formulation::VirtualFrame => "virtual-frame",
            Formulation::VirtualFramePivot => "virtual-frame-pivot",
            Formulation::Odometry => "odometry",
        }
    }
}

impl fmt::Display for Formulation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Formulation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Formulation::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| {
                format!("unknown formulation `{s}` (two-stage, virtual-frame, virtual-frame-pivot, odometry)")
            })
    }
}

/// Why a batch solve failed.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum SolveError {
    /// The graph cannot be solved (empty, disconnected).
    Graph(GraphError),
    /// A factorisation failed.
    Factor(FactorError),
    /// An option this graph's dimension does not have yet.
    Unsupported(&'static str),
}

impl fmt::Display for SolveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SolveError::Graph(e) => e.fmt(f),
            SolveError::Factor(e) => e.fmt(f),
            SolveError::Unsupported(what) => write!(f, "{what} is not available for 3-D graphs"),
        }
    }
}

impl std::error::Error for SolveError {}

impl From<GraphError> for SolveError {
    fn from(e: GraphError) -> Self {
        SolveError::Graph(e)
    }
}

impl From<FactorError> for SolveError {
    fn from(e: FactorError) -> Self {
        SolveError::Factor(e)
    }
}

/// Options of [`solve_batch`].
#[derive(Clone, Debug, Default)]
pub struct BatchOptions {
    /// The linear formulation.
    pub formulation: Formulation,
    /// Run the Levenberg–Marquardt polish after it.
    pub polish: bool,
    /// Polish parameters.
    pub lm: LevenbergMarquardtParams,
    /// GPS fixes (keyframe indices of the graph being solved).
    pub gps: Option<GpsInput>,
    /// Filter loop closures: the robust polish replaces the plain one.
    pub robust: Option<OutlierConfig>,
}

/// What [`solve_batch`] found.
#[derive(Clone, Debug)]
pub struct BatchSolution<P: LiePose = Pose2> {
    /// Final poses, indexed like the graph.
    pub poses: Vec<P>,
    /// χ² of the final poses.
    pub chi2: f64,
    /// χ² of the linear solution, before any polish.
    pub linear_chi2: f64,
    /// Seconds spent in the linear formulation.
    pub linear_seconds: f64,
    /// Seconds spent polishing.
    pub polish_seconds: f64,
    /// The polish report, when it ran.
    pub polish: Option<LmReport<P>>,
    /// For the virtual-frame formulations: the global scale ρ.
    pub rho: Option<f64>,
    /// For the virtual-frame formulations: the median axis length at ρ = 1.
    pub median_axis_length: Option<f64>,
    /// The map→ENU motion, when GPS was given (and had two distinct fixes).
    pub georef: Option<Georef>,
    /// With `robust`: the final switch of each edge (file order).
    pub switches: Option<Vec<f64>>,
}

impl<P: LiePose> BatchSolution<P> {
    /// Total solve time (I/O excluded).
    pub fn seconds(&self) -> f64 {
        self.linear_seconds + self.polish_seconds
    }
}

/// A pose type a whole graph can be solved in.
pub trait BatchPose: LiePose {
    /// [`solve_batch`] on a graph of this pose type.
    fn solve_batch(
        graph: &PoseGraph<Self>,
        options: &BatchOptions,
    ) -> Result<BatchSolution<Self>, SolveError>;
}

impl BatchPose for Pose2 {
    fn solve_batch(
        graph: &PoseGraph<Self>,
        options: &BatchOptions,
    ) -> Result<BatchSolution<Self>, SolveError> {
        solve_planar(graph, options)
    }
}

impl BatchPose for Pose3 {
    fn solve_batch(
        graph: &PoseGraph<Self>,
        options: &BatchOptions,
    ) -> Result<BatchSolution<Self>, SolveError> {
        solve_spatial(graph, options)
    }
}

/// Solves a whole graph at once: the linear initialiser the options name
/// (in 3-D the chordal one), then optionally the polish on g2o's cost, or
/// the robust polish (from the initialiser and from odometry alone). GPS,
/// the virtual-frame formulations, the cycle test and PCM are planar only
/// ([`SolveError::Unsupported`] in 3-D).
pub fn solve_batch<P: BatchPose>(
    graph: &PoseGraph<P>,
    options: &BatchOptions,
) -> Result<BatchSolution<P>, SolveError> {
    P::solve_batch(graph, options)
}

/// [`solve_batch`] in the plane.
fn solve_planar(graph: &PoseGraph, options: &BatchOptions) -> Result<BatchSolution, SolveError> {
    graph.check_connected()?;
    let start = Instant::now();
    let gps = options.gps.as_ref().map(|g| calibrated(graph, g)).transpose()?;
    let gps = gps.as_ref();
    let (mut rho, mut median_axis_length, mut georef) = (None, None, None);
    let poses = match options.formulation {
        Formulation::TwoStage => match gps {
            Some(gps) => {
                let (poses, g) = two_stage::solve_gps(graph, gps)?;
                georef = g;
                poses
            }
            None => two_stage::solve(graph)?,
        },
        Formulation::Odometry => graph.compose_spanning_tree()?,
        Formulation::VirtualFrame | Formulation::VirtualFramePivot => {
            let pivot = match options.formulation {
                Formulation::VirtualFrame => Pivot::Printed,
                _ => Pivot::AxisX,
            };
            let s = virtual_frame::solve_with(graph, pivot, gps)?;
            rho = Some(s.rho);
            median_axis_length = Some(s.median_axis_length);
            s.poses
        }
    };
    if let (Some(gps), None) = (gps, georef) {
        georef = gps.fit(&poses);
    }
    let linear_seconds = start.elapsed().as_secs_f64();
    let linear_chi2 = chi2(graph, &poses);
    let mut switches = None;
    let (poses, polish_report, polish_seconds) = if let Some(filter) = &options.robust {
        // from the linear solution and from odometry alone (which no wrong
        // loop closure bends), the lower robust cost wins
        let start = Instant::now();
        let switchable: Vec<bool> = graph.edges().iter().map(|e| filter.switchable(e)).collect();
        let mut starts = vec![poses.clone()];
        starts.extend(odometry_chain(graph));
        // a batch solve has the machine: the starts are probed two at a time
        let held_out = if filter.pcm() {
            let mut pcm = ConsistencyGraph::default();
            pcm.update(
                graph.len(),
                graph.edges(),
                |e| switchable[e],
                filter.pairwise_chi2,
            );
            let ids: Vec<usize> = (0..switchable.len()).collect();
            pcm.held_out(&ids, &switchable)
        } else {
            Vec::new()
        };
        let held_out = cycles::either(
            held_out,
            cycles::rejected(graph.len(), graph.edges(), &switchable, filter),
        );
        let input = RobustEdges {
            edges: graph.edges(),
            switchable: &switchable,
            held_out: &held_out,
        };
        let sol = robust_polish(input, starts, filter, options.lm, 2, None, Comparison::Stated)?;
        let mut poses = sol.poses;
        if let Some(gps) = gps.filter(|g| g.absolute) {
            let edges: Vec<Edge> = (graph.edges().iter().zip(&sol.switches))
                .map(|(e, s)| Edge {
                    information: e.information.scaled(s * s),
                    ..*e
                })
                .collect();
            // georeferenced afresh on the switched edges; the linear
            // solution's georeference stands when no round runs
            let mut fitted = None;
            if gps
                .georeference(&edges, &mut poses, &mut fitted, options.lm, 2)?
                .is_some()
            {
                georef = fitted;
            }
        }
        switches = Some(sol.switches);
        (poses, None, start.elapsed().as_secs_f64())
    } else if options.polish {
        let start = Instant::now();
        let mut report = polish(Problem::edges(graph.edges()), poses.clone(), options.lm)?;
        if let Some(gps) = gps.filter(|g| g.absolute) {
            // the first round polishes under the linear solution's georeference
            let mut poses = report.poses.clone();
            if let Some(last) = gps.georeference(graph.edges(), &mut poses, &mut georef, options.lm, 2)? {
                report = last;
            }
        }
        let secs = start.elapsed().as_secs_f64();
        (report.poses.clone(), Some(report), secs)
    } else {
        (poses, None, 0.0)
    };
    Ok(BatchSolution {
        chi2: chi2(graph, &poses),
        poses,
        linear_chi2,
        linear_seconds,
        polish_seconds,
        polish: polish_report,
        rho,
        median_axis_length,
        georef,
        switches,
    })
}

/// [`solve_batch`] in space: the chordal two-stage initialiser (or
/// odometry), then optionally the polish on g2o's SE(3) cost, or the
/// robust polish (DCS at six degrees of freedom unless the kernel is set).
fn solve_spatial(
    graph: &PoseGraph<Pose3>,
    options: &BatchOptions,
) -> Result<BatchSolution<Pose3>, SolveError> {
    graph.check_connected()?;
    if options.gps.is_some() {
        return Err(SolveError::Unsupported("GPS"));
    }
    let start = Instant::now();
    let poses = match options.formulation {
        Formulation::TwoStage => chordal::solve(graph)?,
        Formulation::Odometry => graph.compose_spanning_tree()?,
        Formulation::VirtualFrame | Formulation::VirtualFramePivot => {
            return Err(SolveError::Unsupported("the virtual-frame formulation"))
        }
    };
    let linear_seconds = start.elapsed().as_secs_f64();
    let linear_chi2 = chi2(graph, &poses);
    let start = Instant::now();
    let (mut report, mut switches) = (None, None);
    let poses = if let Some(filter) = &options.robust {
        if filter.planar_only() {
            return Err(SolveError::Unsupported("the cycle test and PCM"));
        }
        let mut filter = *filter;
        if filter.kernel == Kernel::default() {
            filter.kernel = Kernel::default_for(6);
        }
        let switchable: Vec<bool> = graph.edges().iter().map(|e| filter.switchable(e)).collect();
        let mut starts = vec![poses];
        starts.extend(odometry_chain(graph));
        let input = RobustEdges {
            edges: graph.edges(),
            switchable: &switchable,
            held_out: &[],
        };
        let sol = robust_polish(input, starts, &filter, options.lm, 2, None, Comparison::Stated)?;
        switches = Some(sol.switches);
        sol.poses
    } else if options.polish {
        let r = polish(Problem::edges(graph.edges()), poses, options.lm)?;
        let poses = r.poses.clone();
        report = Some(r);
        poses
    } else {
        poses
    };
    let polish_seconds = start.elapsed().as_secs_f64();
    Ok(BatchSolution {
        chi2: chi2(graph, &poses),
        poses,
        linear_chi2,
        linear_seconds,
        polish_seconds,
        polish: report,
        rho: None,
        median_axis_length: None,
        georef: None,
        switches,
    })
}

/// Poses composed along odometry alone, when odometry links every keyframe.
fn odometry_chain<P: LiePose>(graph: &PoseGraph<P>) -> Option<Vec<P>> {
    let odometry = graph.edges().iter().filter(|e| e.kind == EdgeKind::Odometry);
    let chain = PoseGraph::from_parts(graph.keyframes().to_vec(), odometry.copied().collect()).ok()?;
    chain.compose_spanning_tree().ok()
}

/// `gps` with its weight set to the graph's variance factor (without GPS,
/// two-stage), when it asks for calibration.
fn calibrated(graph: &PoseGraph, gps: &GpsInput) -> Result<GpsInput, SolveError> {
    let mut gps = gps.clone();
    if gps.calibrate {
        let chi2 = chi2(graph, &two_stage::solve(graph)?);
        gps.weight = variance_factor(chi2, graph.edges().len(), graph.len(), 3);
    }
    Ok(gps)
}
