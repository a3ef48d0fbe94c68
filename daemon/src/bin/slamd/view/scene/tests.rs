use super::*;
use nalgebra::Vector3 as V3;

fn planar(id: u64, x: f64, y: f64, theta: f64) -> Pose {
    Pose {
        id,
        x,
        y,
        qz: (theta / 2.0).sin(),
        qw: (theta / 2.0).cos(),
        theta,
        ..Default::default()
    }
}

fn switch(from: u64, to: u64, weight: f64, pending: bool) -> Switch {
    Switch {
        from,
        to,
        weight,
        pending: u32::from(pending),
        ..Default::default()
    }
}

fn square() -> Frame {
    Frame {
        header: SnapshotHeader {
            dimension: 2,
            version: 7,
            solved_at_ns: 3_500_000_001,
            ..Default::default()
        },
        poses: vec![
            planar(10, 0.0, 0.0, 0.0),
            planar(11, 1.0, 0.0, 0.0),
            planar(12, 1.0, 1.0, 0.0),
            planar(13, 0.0, 1.0, 0.0),
        ],
        loops: vec![
            switch(10, 13, 1.0, false),
            switch(11, 13, 0.2, false),
            switch(10, 12, 0.0, true),
            switch(10, 99, 1.0, false),
        ],
    }
}

#[test]
fn timestamps_split_into_seconds_and_nanoseconds() {
    assert_eq!(timestamp(3_500_000_001), Timestamp::new(3, 500_000_001));
}

#[test]
fn the_graph_draws_the_odometry_chain_and_each_loop_closure_by_state() {
    let f = square();
    let update = f.graph(&f.loop_closures());
    assert_eq!(update.entities.len(), 1, "no covariance: no ellipsoid");
    let g = &update.entities[0];
    assert_eq!(g.id, "graph");
    let xy = |l: &foxglove::messages::LinePrimitive| l.points.iter().map(|p| (p.x, p.y)).collect::<Vec<_>>();
    assert_eq!(g.lines[0].r#type, LineType::LineStrip as i32);
    assert_eq!(xy(&g.lines[0]), [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
    // kept 10–13, off 11–13, pending 10–12; the one to keyframe 99 is not drawn
    assert_eq!(xy(&g.lines[1]), [(0.0, 0.0), (0.0, 1.0)]);
    assert_eq!(xy(&g.lines[2]), [(1.0, 0.0), (0.0, 1.0)]);
    assert_eq!(xy(&g.lines[3]), [(0.0, 0.0), (1.0, 1.0)]);
    let counts: Vec<(&str, &str)> = g
        .metadata
        .iter()
        .map(|m| (m.key.as_str(), m.value.as_str()))
        .collect();
    assert_eq!(counts, [("kept", "1"), ("off", "1"), ("pending", "1")]);
}

#[test]
fn the_trajectory_carries_every_pose_as_the_snapshot_has_it() {
    let mut f = square();
    f.poses[2] = planar(12, 1.25, -3.5, 2.0);
    let t = f.trajectory();
    assert_eq!(t.frame_id, "map");
    assert_eq!(t.timestamp, Some(Timestamp::new(3, 500_000_001)));
    let p = &t.poses[2];
    let pos = p.position.as_ref().unwrap();
    let q = p.orientation.as_ref().unwrap();
    assert_eq!((pos.x, pos.y, pos.z), (1.25, -3.5, 0.0));
    assert_eq!((q.z, q.w), ((1.0f64).sin(), (1.0f64).cos()));
}

#[test]
fn the_page_map_lists_ids_positions_and_loop_states() {
    let f = square();
    let m: serde_json::Value = serde_json::from_slice(&f.page_map(&f.loop_closures())).unwrap();
    assert_eq!(m["version"], 7);
    assert_eq!(m["poses"][3], serde_json::json!([13, 0.0, 1.0]));
    assert_eq!(
        m["loops"],
        serde_json::json!([[10, 13, "kept"], [11, 13, "off"], [10, 12, "pending"]])
    );
}

/// The covariance an ellipsoid stands for: `A diag((s / 2k)²) Aᵀ`.
fn covariance_of(s: &SpherePrimitive) -> Matrix3<f64> {
    let o = s.pose.as_ref().unwrap().orientation.as_ref().unwrap();
    let a =
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(o.w, o.x, o.y, o.z)).to_rotation_matrix();
    let size = s.size.as_ref().unwrap();
    let d = V3::new(size.x, size.y, size.z).map(|l| (l / (2.0 * SIGMAS)).powi(2));
    a.matrix() * Matrix3::from_diagonal(&d) * a.matrix().transpose()
}

#[test]
fn a_planar_covariance_turns_with_its_pose() {
    // σx = 2 m, σy = 1 m along the pose's own axes; the pose faces +y
    let p = planar(5, 3.0, 4.0, std::f64::consts::FRAC_PI_2);
    let mut h = SnapshotHeader {
        dimension: 2,
        has_covariance: 1,
        covariance_keyframe: 5,
        ..Default::default()
    };
    h.covariance[..6].copy_from_slice(&[4.0, 0.0, 0.0, 1.0, 0.0, 0.01]);
    let s = ellipsoid(&h, &p).unwrap();
    let c = covariance_of(&s);
    // in the map frame: 1 m² along x, 4 m² along y, flat in z
    let want = Matrix3::new(1.0, 0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 0.0);
    assert!((c - want).abs().max() < 1e-5, "{c}");
    let at = s.pose.as_ref().unwrap().position.as_ref().unwrap();
    assert_eq!((at.x, at.y), (3.0, 4.0));
    h.covariance_keyframe = 6;
    assert!(ellipsoid(&h, &p).is_none(), "the covariance of another keyframe");
}

#[test]
fn a_spatial_covariance_keeps_its_cross_terms() {
    let p = Pose {
        id: 1,
        qw: 1.0,
        ..Default::default()
    };
    let mut h = SnapshotHeader {
        dimension: 3,
        has_covariance: 1,
        covariance_keyframe: 1,
        ..Default::default()
    };
    // (x, y, z) block [[2, 0.5, 0], [0.5, 1, 0.2], [0, 0.2, 3]] in the
    // upper triangle of the 6×6
    h.covariance[0] = 2.0;
    h.covariance[1] = 0.5;
    h.covariance[6] = 1.0;
    h.covariance[7] = 0.2;
    h.covariance[11] = 3.0;
    let c = covariance_of(&ellipsoid(&h, &p).unwrap());
    let want = Matrix3::new(2.0, 0.5, 0.0, 0.5, 1.0, 0.2, 0.0, 0.2, 3.0);
    assert!((c - want).abs().max() < 1e-9, "{c}");
}

#[test]
fn locations_appear_once_georeferenced_and_come_back_to_east_north_up() {
    let mut f = square();
    assert!(f.locations().is_none());
    f.header.georeferenced = 1;
    f.header.has_origin = 1;
    f.header.origin = [45.0, 9.0, 120.0];
    f.poses[3].east = 250.0;
    f.poses[3].north = -40.0;
    f.poses[3].up = 2.0;
    let (all, newest) = f.locations().unwrap();
    assert_eq!(all.fixes.len(), 4);
    assert_eq!(newest, all.fixes[3]);
    let frame = LocalFrame::new(Geodetic {
        lat: 45.0,
        lon: 9.0,
        height: 120.0,
    });
    let (e, n, u) = frame.to_enu(&Geodetic {
        lat: newest.latitude,
        lon: newest.longitude,
        height: newest.altitude,
    });
    assert!((e - 250.0).abs() < 1e-6 && (n + 40.0).abs() < 1e-6 && (u - 2.0).abs() < 1e-6);
}

#[test]
fn health_reports_the_counters_and_the_latency() {
    let h = SnapshotHeader {
        keyframes: 12,
        pending: 2,
        chi2: 3.5,
        ..Default::default()
    };
    let s = DaemonStatus {
        latency_p99_us: 800.0,
        ..Default::default()
    };
    let v = health(&h, Some(&s));
    assert_eq!(
        (v["keyframes"].as_u64(), v["pending"].as_u64()),
        (Some(12), Some(2))
    );
    assert_eq!(
        (v["chi2"].as_f64(), v["latency_p99_us"].as_f64()),
        (Some(3.5), Some(800.0))
    );
    assert!(health(&h, None).get("latency_p99_us").is_none());
}
