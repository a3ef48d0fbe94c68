//! Batch solve time per dataset and formulation (targets on 2 cores:
//! City10000 two-stage ≤ 50 ms, with polish ≤ 300 ms).
//!
//! `cargo bench -p slamd-benches --bench linear_solve`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use slamd::solver::{solve_batch, BatchOptions, Formulation};
use std::time::Duration;

const DATASETS: [&str; 7] = [
    "manhattanolson3500_g2oversion.g2o",
    "city10000.g2o",
    "intel_sesync.g2o",
    "input_intel_g2o.g2o",
    "mit_killian.g2o",
    "ring.g2o",
    "ringcity.g2o",
];

fn batch(c: &mut Criterion) {
    let mut group = c.benchmark_group("batch");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(3))
        .warm_up_time(Duration::from_millis(500));
    for name in DATASETS {
        let graph = slamd_tests::read(name);
        let variants = [
            ("two-stage", Formulation::TwoStage, false),
            ("virtual-frame", Formulation::VirtualFrame, false),
            ("two-stage+polish", Formulation::TwoStage, true),
        ];
        for (label, formulation, polish) in variants {
            let opts = BatchOptions {
                formulation,
                polish,
                ..Default::default()
            };
            group.bench_with_input(BenchmarkId::new(label, name), &graph, |b, g| {
                b.iter(|| solve_batch(g, &opts).expect("solvable"))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, batch);
criterion_main!(benches);
