"""The `slamd` package: files, batch solves, the engine, marginals, errors
and a real daemon, checked against the `slamd` command and exact worlds."""

import json
import math
import subprocess
import time

import numpy as np
import pytest

import slamd
from conftest import REPO, clean_env, dataset, slamd_bin


def cli_solve(path):
    run = subprocess.run([str(slamd_bin()), "solve", str(path), "--polish", "--json"],
                         capture_output=True, text=True, env=clean_env(), check=True)
    return json.loads(run.stdout)


def test_manhattan_solves_to_the_commands_optimum():
    path = dataset("manhattanolson3500.g2o")
    graph = slamd.read(path)
    assert (graph.dimension, len(graph)) == (2, 3500)
    assert graph.edges.shape == (5598, 2) and graph.measurements.shape == (5598, 3)
    assert graph.information.shape == (5598, 6)
    assert graph.kinds.count("odometry") == 3499
    result = slamd.solve(graph, polish=True)
    assert result.poses.shape == (3500, 3) and list(result.ids[:3]) == [0, 1, 2]
    assert abs(result.chi2 - 146.077) < 1e-3
    assert math.isclose(result.chi2, cli_solve(path)["chi2"], rel_tol=1e-9)


def test_a_spatial_file_solves_to_its_optimum():
    graph = slamd.read(dataset("3d/sphere2500.g2o"))
    result = slamd.solve(graph)
    assert graph.dimension == 3 and result.poses.shape == (2500, 7)
    assert abs(result.chi2 - 727.15) < 1e-2
    # unit quaternions
    assert np.allclose(np.linalg.norm(result.poses[:, 3:], axis=1), 1.0)


def test_the_readme_script_runs(monkeypatch):
    """The README's Python block, as a newcomer pastes it."""
    text = (REPO / "README.md").read_text()
    block = text.split("```python\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(REPO)
    out = {}
    exec(compile(block, "README.md", "exec"), out)
    assert abs(out["result"].chi2 - 146.077) < 1e-3


def square_walk():
    """A noise-free 4 × 4 m square walked twice, with its exact steps."""
    step = (1.0, 0.0, math.pi / 2)
    return [step] * 8


def test_engine_recovers_an_exact_loop_and_its_marginals_are_consistent():
    engine = slamd.Engine(background=False)
    info = [4.0, 0.0, 0.0, 4.0, 0.0, 100.0]
    for k, step in enumerate(square_walk()):
        engine.add_keyframe(k)
        if k == 0:
            continue
        engine.add_edge(k - 1, k, step, info)
        engine.update()
    engine.add_keyframe(8)
    engine.add_edge(7, 8, (1.0, 0.0, math.pi / 2), np.diag([4.0, 4.0, 100.0]))
    engine.add_edge(0, 8, (0.0, 0.0, 0.0), info, kind="loop_closure")
    engine.update()
    snap = engine.snapshot()
    assert (len(snap), snap.keyframes, snap.edges, snap.pending) == (9, 9, 9, 0)
    assert snap.chi2 < 1e-18
    expected = {0: (0, 0), 1: (1, 0), 2: (1, 1), 3: (0, 1), 4: (0, 0), 8: (0, 0)}
    for i, (x, y) in expected.items():
        row = snap.poses[list(snap.ids).index(i)]
        assert abs(row[0] - x) < 1e-9 and abs(row[1] - y) < 1e-9
    assert list(engine.switches()) == [1.0] * 9
    assert list(snap.timestamps) == [0] * 9 and snap.covariance is None
    # the gauge is fixed; the loop's far side (keyframe 4) is the least sure
    assert np.all(engine.marginal(0) == 0.0)
    variances = [engine.marginal(k)[0, 0] + engine.marginal(k)[1, 1] for k in range(9)]
    assert 0.0 < variances[1] < variances[2] < variances[3] < variances[4]
    assert variances[4] > variances[7] > variances[8] > 0.0
    joint = engine.joint_marginal(2, 6)
    assert joint.shape == (6, 6) and np.allclose(joint, joint.T, atol=1e-15)
    assert np.allclose(joint[:3, :3], engine.marginal(2), rtol=1e-12)
    assert np.allclose(joint[3:, 3:], engine.marginal(6), rtol=1e-12)


def test_a_loop_closure_waits_out_of_the_estimate_until_the_filter_decides():
    engine = slamd.Engine()  # the filter's judge on its own thread
    info = [4.0, 0.0, 0.0, 4.0, 0.0, 100.0]
    for k, step in enumerate(square_walk()):
        engine.add_keyframe(k)
        if k > 0:
            engine.add_edge(k - 1, k, step, info)
        engine.update()
    engine.add_keyframe(8)
    engine.add_edge(7, 8, (1.0, 0.0, math.pi / 2), info)
    engine.add_edge(0, 8, (0.0, 0.0, 0.0), info, kind="loop_closure")
    engine.update()
    # the judge decides before the next keyframe or at the end of the stream
    assert engine.snapshot().pending == 1 and engine.switches()[-1] == 0.0
    engine.resolve_now()
    snap = engine.snapshot()
    assert snap.pending == 0 and engine.switches()[-1] == 1.0 and snap.chi2 < 1e-18


def test_spatial_engine_takes_quaternion_poses():
    engine = slamd.Engine(3, background=False)
    info = np.eye(6) * 10.0
    engine.add_keyframe(0)
    engine.add_keyframe(1)
    half = math.sqrt(0.5)
    engine.add_edge(0, 1, (0.0, 0.0, 2.0, 0.0, 0.0, half, half), info)
    engine.update()
    snap = engine.snapshot()
    assert np.allclose(snap.poses[1], (0.0, 0.0, 2.0, 0.0, 0.0, half, half), atol=1e-12)
    assert engine.marginal(1).shape == (6, 6)


@pytest.mark.parametrize("call, message", [
    (lambda e: e.add_edge(0, 9, (1, 0, 0), [1, 0, 0, 1, 0, 1]), "edge refers to unknown keyframe 9"),
    (lambda e: e.add_keyframe(0), "duplicate keyframe id 0"),
    (lambda e: e.add_edge(0, 1, (math.nan, 0, 0), [1, 0, 0, 1, 0, 1]), "non-finite value in edge measurement"),
    (lambda e: e.add_edge(0, 1, (1, 0), [1, 0, 0, 1, 0, 1]), "a planar pose is (x, y, theta); got 2 numbers"),
    (lambda e: e.add_edge(0, 1, (1, 0, 0), [1, 0, 0]), "information: 6 upper-triangle numbers are needed; got 3"),
    (lambda e: e.add_edge(0, 1, (1, 0, 0), [1, 3, 0, 1, 0, 1]), "not positive definite"),
    (lambda e: e.add_edge(0, 1, (1, 0, 0), [1, 0, 0, 1, 0, 1], kind="guess"), "edge kind \"guess\""),
    (lambda e: e.marginal(1), "no covariance for keyframe 1: it has no edge to the map yet"),
    (lambda e: slamd.Engine(4), "dimension 4: 2 or 3"),
])
def test_bad_input_raises_slamds_message_and_changes_nothing(call, message):
    engine = slamd.Engine(background=False)
    engine.add_keyframe(0)
    engine.add_keyframe(1)
    with pytest.raises(slamd.SlamdError, match=None) as caught:
        call(engine)
    assert message in str(caught.value)
    assert isinstance(caught.value, ValueError)
    snap = engine.snapshot()
    assert (snap.keyframes, snap.edges) == (2, 0)


def test_a_malformed_file_names_its_line(tmp_path):
    path = tmp_path / "bad.g2o"
    path.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 zero 1 0 0 1 0 1\n")
    with pytest.raises(slamd.SlamdError) as caught:
        slamd.read(path)
    assert str(caught.value).endswith("bad.g2o:3: EDGE_SE2: `zero` is not a number")
    with pytest.raises(slamd.SlamdError, match="No such file"):
        slamd.read(tmp_path / "missing.g2o")


def test_frontend_and_snapshots_talk_to_a_real_daemon(daemons):
    _, start = daemons
    daemon = start("package")
    snapshots = slamd.Snapshots(daemon.namespace)
    frontend = slamd.Frontend(daemon.namespace)
    info = [4.0, 0.0, 0.0, 4.0, 0.0, 100.0]
    for k, step in enumerate(square_walk()):
        frontend.add_keyframe(k, timestamp_ns=1_000 * k)
        if k > 0:
            frontend.add_edge(k - 1, k, step, info)
        frontend.flush()
    frontend.add_edge(0, 7, (0.0, 1.0, -math.pi / 2), info, kind="loop_closure")
    frontend.flush()
    assert frontend.wait_acknowledged(timeout=20.0)
    # the newest keyframe's covariance, as the same engine in-process gives
    # it at the end of the stream (the loop closure decided, re-solved)
    engine = slamd.Engine()
    for k, step in enumerate(square_walk()):
        engine.add_keyframe(k)
        if k > 0:
            engine.add_edge(k - 1, k, step, info)
    engine.add_edge(0, 7, (0.0, 1.0, -math.pi / 2), info, kind="loop_closure")
    engine.resolve_now()
    expected = engine.marginal(7)

    def at_rest(snap):
        # the loop closure counts once the filter has decided it, and the
        # daemon re-solves once input pauses
        return (snap.edges, len(snap), snap.pending, snap.covariance_keyframe) == (8, 8, 0, 7) and np.allclose(
            snap.covariance, expected, rtol=1e-9, atol=1e-15
        )

    snap = None
    for _ in range(100):
        snap = snapshots.wait(timeout=1.0) or snap
        if snap is not None and at_rest(snap):
            break
    assert snap is not None and at_rest(snap), snap and (snap.pending, snap.covariance)
    row = snap.poses[list(snap.ids).index(6)]
    assert np.allclose(row[:2], (1.0, 1.0), atol=1e-6)
    assert snap.chi2 < 1e-9
    assert list(snap.timestamps) == [1_000 * k for k in range(8)]
    with pytest.raises(slamd.SlamdError):
        slamd.Frontend(daemon.namespace, dimension=5)
    # a message not sent is never acknowledged; one sent to a daemon that
    # is gone waits out the silence bound only
    assert not frontend.wait_acknowledged(frontend.add_keyframe(8) + 1, timeout=30.0)
    daemon.shut_down()
    sequence = frontend.add_keyframe(9)
    started = time.monotonic()
    assert not frontend.wait_acknowledged(sequence, timeout=1.0)
    assert time.monotonic() - started < 5.0
