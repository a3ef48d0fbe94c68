//! The built-in synthetic worlds: a seeded Manhattan-style drive with noisy
//! odometry, loop closures and known ground truth.
//!
//! The robot drives 1 m steps along the streets of a square city of
//! `block`-metre blocks, turning at random at intersections and turning back
//! at the city limits. Each step is an odometry edge; whenever it passes
//! within `closure_radius` of a pose it visited more than `min_gap` steps
//! earlier, it may recognise the place and add a loop closure. Measurements
//! are the true relative poses plus Gaussian noise with the σ's below, and
//! every edge carries the matching information. The city's side grows with
//! √poses so that revisits stay frequent at any size (tests use hundreds of
//! poses, scale benchmarks up to 1,000,000). In 3-D ([`generate_building`]) the same
//! drive climbs a building, a floor at a time. [`gps_fixes`] places a
//! world on the globe and takes noisy GPS fixes of its true positions.

use crate::geometry::Pose2;
use crate::gps::{Geodetic, LocalFrame};
use crate::graph::{EdgeKind, Information, Information6, Pose3, PoseGraph, RigidMotion};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use slamd_types::{FixInput, KeyframeId};
use std::collections::HashMap;
use std::f64::consts::FRAC_PI_2;

/// Parameters of the synthetic world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldParams {
    /// Number of keyframes.
    pub poses: usize,
    /// RNG seed: the same seed gives the same world, bit for bit.
    pub seed: u64,
    /// Odometry translation noise σ per axis (m).
    pub sigma_xy: f64,
    /// Odometry heading noise σ (rad).
    pub sigma_theta: f64,
    /// Street block length (m).
    pub block: usize,
    /// A pose this close to an old one may close a loop (m).
    pub closure_radius: f64,
    /// Minimum index gap for a loop closure.
    pub min_gap: usize,
    /// Probability that a candidate loop closure is recognised.
    pub closure_probability: f64,
}

impl Default for WorldParams {
    fn default() -> Self {
        Self {
            poses: 2000,
            seed: 1,
            sigma_xy: 0.05,
            sigma_theta: 0.01,
            block: 5,
            closure_radius: 0.6,
            min_gap: 30,
            closure_probability: 0.5,
        }
    }
}

/// A generated world: the graph (edges in time order) and the truth, in
/// the plane ([`generate`]) or in space ([`generate_building`]).
#[derive(Clone, Debug)]
pub struct World<P: RigidMotion = Pose2> {
    /// Keyframes `0..poses` and their noisy edges.
    pub graph: PoseGraph<P>,
    /// The true pose of every keyframe; keyframe 0 at the origin.
    pub truth: Vec<P>,
}

/// A standard normal sample (Box–Muller).
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
    let v: f64 = rng.random();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// Generates the world for `params`.
pub fn generate(params: &WorldParams) -> World {
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
    let n = params.poses.max(2);
    let block = params.block.max(1) as i64;
    // side in blocks: a city the drive covers a few times over
    let side = (((n as f64).sqrt() / block as f64 * 1.5).ceil() as i64).max(2) * block;
    let info = Information::from_variances(
        params.sigma_xy.powi(2),
        params.sigma_xy.powi(2),
        params.sigma_theta.powi(2),
    )
    .expect("positive σ");

    // truth: integer grid positions, headings multiples of π/2
    let (mut x, mut y, mut dir) = (0i64, 0i64, 0i64);
    let mut truth = Vec::with_capacity(n);
    truth.push(Pose2::IDENTITY);
    for k in 1..n {
        if k > 1 && x % block == 0 && y % block == 0 {
            dir = (dir + [0, 1, 3][rng.random_range(0..3)]) % 4;
        }
        let (dx, dy) = [(1, 0), (0, 1), (-1, 0), (0, -1)][dir as usize];
        if !(0..=side).contains(&(x + dx)) || !(0..=side).contains(&(y + dy)) {
            dir = (dir + 2) % 4; // dead end at the city limit: turn back
        }
        let (dx, dy) = [(1, 0), (0, 1), (-1, 0), (0, -1)][dir as usize];
        x += dx;
        y += dy;
        let theta = crate::geometry::wrap_angle(dir as f64 * FRAC_PI_2);
        truth.push(Pose2::new(x as f64, y as f64, theta));
    }

    let noisy = |rng: &mut ChaCha8Rng, t: Pose2| {
        Pose2::new(
            t.x + params.sigma_xy * gaussian(rng),
            t.y + params.sigma_xy * gaussian(rng),
            crate::geometry::wrap_angle(t.theta + params.sigma_theta * gaussian(rng)),
        )
    };
    let graph = drive_edges(&truth, params, &mut rng, info, noisy);
    World { graph, truth }
}

/// The edges of a drive along `truth`, keyframe `k` with id `k`: a noisy
/// odometry edge into every keyframe and, where the drive passes within
/// `closure_radius` of a keyframe more than `min_gap` steps older, a noisy
/// loop closure to the most recent such keyframe with probability
/// `closure_probability`. Old keyframes are found through the 1 m cells
/// around the position (same height only).
fn drive_edges<P: RigidMotion>(
    truth: &[P],
    params: &WorldParams,
    rng: &mut ChaCha8Rng,
    info: P::Information,
    noisy: impl Fn(&mut ChaCha8Rng, P) -> P,
) -> PoseGraph<P> {
    let n = truth.len();
    let mut graph = PoseGraph::<P>::default();
    for id in 0..n as u64 {
        graph.add_keyframe(id, None).expect("fresh ids");
    }
    let position = |k: usize| nalgebra::Vector3::from(truth[k].position3());
    let cell = |k: usize| position(k).map(|v| v.round() as i64);
    let mut visited: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::new();
    let reach = params.closure_radius.ceil() as i64;
    for k in 0..n {
        let c = cell(k);
        if k > 0 {
            let m = noisy(rng, truth[k - 1].between(&truth[k]));
            graph
                .add_edge(k as u64 - 1, k as u64, m, info, EdgeKind::Odometry)
                .expect("valid odometry");
            let mut candidates = Vec::new();
            for ox in -reach..=reach {
                for oy in -reach..=reach {
                    let near = visited.get(&(c.x + ox, c.y + oy, c.z)).map(Vec::as_slice);
                    for &j in near.unwrap_or(&[]) {
                        let d = (position(j) - position(k)).norm();
                        if k - j > params.min_gap && d <= params.closure_radius {
                            candidates.push(j);
                        }
                    }
                }
            }
            // at most one closure per keyframe, to the most recent match
            if let Some(&j) = candidates.iter().max() {
                if rng.random_bool(params.closure_probability) {
                    let m = noisy(rng, truth[j].between(&truth[k]));
                    graph
                        .add_edge(j as u64, k as u64, m, info, EdgeKind::LoopClosure)
                        .expect("valid closure");
                }
            }
        }
        visited.entry((c.x, c.y, c.z)).or_default().push(k);
    }
    graph
}

/// Storey height of [`generate_building`]'s building (m).
pub const STOREY: f64 = 3.0;

/// How many times better [`generate_building`]'s roll and pitch are measured
/// than its heading.
pub const GRAVITY_ALIGNED: f64 = 10.0;

/// A building of `storeys` floors: the drive of [`generate`] split into
/// `storeys + 1` equal parts, part `f` on floor `f` (`z = f · STOREY`) and
/// the last back on the ground floor, each floor reached by a lift at the
/// spot where the drive got to (one odometry step straight up or down).
/// The rides close one loop through every floor; other loop closures join
/// keyframes on one floor, by the same rule as in 2-D. Every measurement
/// carries noise of σ `sigma_xy` per axis, `sigma_theta` in yaw and
/// `sigma_theta / GRAVITY_ALIGNED` in roll and pitch, and the matching
/// information.
pub fn generate_building(params: &WorldParams, storeys: usize) -> World<Pose3> {
    let storeys = storeys.max(1);
    let plan = generate(params).truth;
    let n = plan.len();
    // parts 0..storeys on floors 0, 1, …, then back on the ground floor,
    // so the lift rides close a loop through every floor
    let floor = |k: usize| (k * (storeys + 1) / n) % storeys;
    // the plan's steps, except that where the floor changes the step is
    // the lift: straight up or down, heading kept
    let mut truth = vec![Pose3::IDENTITY];
    for k in 1..n {
        let step = if floor(k) != floor(k - 1) {
            let rise = STOREY * (floor(k) as f64 - floor(k - 1) as f64);
            Pose3::from_xyz_rpy([0.0, 0.0, rise, 0.0, 0.0, 0.0])
        } else {
            let s = plan[k - 1].between(&plan[k]);
            Pose3::from_xyz_rpy([s.x, s.y, 0.0, 0.0, 0.0, s.theta])
        };
        let next = truth[k - 1].compose(&step);
        truth.push(next);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed ^ 0x3d3d_3d3d);
    // roll and pitch are observed through gravity (a visual-inertial
    // frontend's IMU): their noise is a tenth of the heading's
    let (sx, st) = (params.sigma_xy, params.sigma_theta);
    let sg = st / GRAVITY_ALIGNED;
    let info = {
        let (t, g, r) = (1.0 / (sx * sx), 1.0 / (sg * sg), 1.0 / (st * st));
        // the quaternion vector is half the angles: Ω_q = 4 Ω_angles
        let mut u = [0.0; 21];
        for (i, v) in [
            (0, t),
            (6, t),
            (11, t),
            (15, 4.0 * g),
            (18, 4.0 * g),
            (20, 4.0 * r),
        ] {
            u[i] = v;
        }
        Information6::from_upper(u).expect("positive σ")
    };
    let noisy = |rng: &mut ChaCha8Rng, t: Pose3| {
        let d = [sx, sx, sx, sg, sg, st].map(|s| s * gaussian(rng));
        t.compose(&Pose3::from_xyz_rpy(d))
    };
    let graph = drive_edges(&truth, params, &mut rng, info, noisy);
    World { graph, truth }
}

/// Where a synthetic world lies on the globe and how its GPS is taken.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpsParams {
    /// The map frame's origin.
    pub origin: Geodetic,
    /// The heading of the map's x axis, counter-clockwise from east (rad).
    pub heading: f64,
    /// A fix at every `every`-th keyframe.
    pub every: usize,
    /// Noise σ of east, north and height (m).
    pub sigma: f64,
    /// RNG seed of the noise.
    pub seed: u64,
}

impl Default for GpsParams {
    fn default() -> Self {
        Self {
            origin: Geodetic {
                lat: 45.5026,
                lon: 9.1566,
                height: 130.0,
            },
            heading: 0.5,
            every: 10,
            sigma: 1.5,
            seed: 1,
        }
    }
}

/// GPS fixes of every [`GpsParams::every`]-th of `positions` (a keyframe
/// and its true map-frame `(x, y, z)`): the position turned by the heading
/// into east-north-up at the origin, plus Gaussian noise of σ on each
/// axis, as WGS84 with that covariance.
pub fn gps_fixes(
    positions: impl IntoIterator<Item = (KeyframeId, [f64; 3])>,
    p: &GpsParams,
) -> Vec<FixInput> {
    let mut rng = ChaCha8Rng::seed_from_u64(p.seed);
    let frame = LocalFrame::new(p.origin);
    let (s, c) = p.heading.sin_cos();
    let var = p.sigma * p.sigma;
    (positions.into_iter().step_by(p.every.max(1)))
        .map(|(keyframe, [x, y, z])| {
            let east = c * x - s * y + p.sigma * gaussian(&mut rng);
            let north = s * x + c * y + p.sigma * gaussian(&mut rng);
            let up = z + p.sigma * gaussian(&mut rng);
            FixInput {
                keyframe,
                position: frame.to_geodetic(east, north, up),
                covariance: [var, 0.0, 0.0, var],
                height_variance: Some(var),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_world_other_seed_other_world() {
        let p = WorldParams {
            poses: 300,
            ..Default::default()
        };
        let (a, b) = (generate(&p), generate(&p));
        assert_eq!(a.truth, b.truth);
        assert_eq!(a.graph.edges(), b.graph.edges());
        let c = generate(&WorldParams { seed: 2, ..p });
        assert_ne!(a.truth, c.truth);
    }

    #[test]
    fn the_building_has_its_storeys_lifts_and_loop_closures_on_each_floor() {
        let p = WorldParams {
            poses: 1500,
            ..Default::default()
        };
        let w = generate_building(&p, 3);
        assert_eq!(w.graph.len(), 1500);
        // three floors, 3 m apart, two rides up and one down to the ground
        // floor
        let heights: std::collections::BTreeSet<i64> = w
            .truth
            .iter()
            .map(|t| (t.translation.z * 1e6).round() as i64)
            .collect();
        assert_eq!(
            heights.into_iter().collect::<Vec<_>>(),
            vec![0, 3_000_000, 6_000_000]
        );
        let lifts = (1..1500)
            .filter(|&k| (w.truth[k].translation.z - w.truth[k - 1].translation.z).abs() > 1.0)
            .count();
        assert_eq!(lifts, 3);
        assert!(
            w.truth[1499].translation.z.abs() < 1e-9,
            "the drive ends on the ground floor"
        );
        let closures: Vec<_> = w
            .graph
            .edges()
            .iter()
            .filter(|e| e.kind == EdgeKind::LoopClosure)
            .collect();
        assert!(closures.len() > 50, "only {} loop closures", closures.len());
        for e in closures {
            let dz = w.truth[e.from].translation.z - w.truth[e.to].translation.z;
            assert!(dz.abs() < 1e-9, "a loop closure across floors");
        }
        assert_eq!(generate_building(&p, 3).graph.edges(), w.graph.edges());
    }

    #[test]
    fn world_has_loop_closures_and_consistent_truth() {
        let w = generate(&WorldParams {
            poses: 1000,
            ..Default::default()
        });
        assert_eq!(w.graph.len(), 1000);
        let closures = w
            .graph
            .edges()
            .iter()
            .filter(|e| e.kind == EdgeKind::LoopClosure)
            .count();
        assert!(closures > 50, "only {closures} loop closures");
        // every step is one metre on the grid
        for k in 1..w.truth.len() {
            let d = (w.truth[k].position() - w.truth[k - 1].position()).norm();
            assert!((d - 1.0).abs() < 1e-12);
        }
        // edges are in time order
        assert!(w.graph.edges().windows(2).all(|e| e[0].newer() <= e[1].newer()));
    }

    #[test]
    fn gps_fixes_lie_at_the_turned_truth_within_their_noise() {
        let p = GpsParams::default();
        let truth: Vec<(KeyframeId, [f64; 3])> =
            (0..95).map(|i| (i, [i as f64, 0.5 * i as f64, 2.0])).collect();
        let fixes = gps_fixes(truth.iter().copied(), &p);
        assert_eq!(fixes.len(), 10, "keyframes 0, 10, …, 90");
        let frame = LocalFrame::new(p.origin);
        let (s, c) = p.heading.sin_cos();
        let mut sum_sq = 0.0;
        for (f, (k, [x, y, z])) in fixes.iter().zip(truth.iter().step_by(10)) {
            assert_eq!(f.keyframe, *k);
            let (e, n, u) = frame.to_enu(&f.position);
            let d = [e - (c * x - s * y), n - (s * x + c * y), u - z];
            assert!(d.iter().all(|v| v.abs() < 5.0 * p.sigma), "{d:?}");
            sum_sq += d.iter().map(|v| v * v).sum::<f64>();
            assert_eq!(f.covariance, [2.25, 0.0, 0.0, 2.25]);
        }
        let rms = (sum_sq / 30.0).sqrt();
        assert!(
            rms > 0.5 * p.sigma && rms < 1.5 * p.sigma,
            "noise of σ: rms {rms}"
        );
    }
}
