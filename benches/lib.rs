//! slamd's benchmarks: criterion targets (`cargo bench -p slamd-benches`)
//! and peer-comparison scripts (`python3 benches/peer_gtsam.py`). This
//! library is empty; the targets live beside it.
