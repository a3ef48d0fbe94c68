"""The pure-Python iceoryx2 frontend reaches the same optimum as `slamd replay`.

Two daemons run on fresh namespaces: the example streams Manhattan into
one, `slamd replay --namespace` into the other, and both final χ² must
agree to 1e-9 relative.

Environment:
    SLAMD_BIN       the slamd binary (default <repo>/target/debug/slamd)
    SLAMD_DATASETS  the datasets directory (default <repo>/../shared/datasets)
"""

import json
import subprocess
import sys

import iceoryx2  # noqa: F401  (the example needs it: pip install iceoryx2==0.10.0)

from conftest import REPO, clean_env, dataset

EXAMPLE = REPO / "python" / "examples" / "iceoryx2_frontend.py"
MANHATTAN = "manhattanolson3500.g2o"
RUN_TIMEOUT_S = 300


def last_json_line(stdout):
    lines = [line for line in stdout.splitlines() if line.strip()]
    assert lines, "no output"
    return json.loads(lines[-1])


def test_python_frontend_matches_slamd_replay(daemons):
    binary, start = daemons
    graph = dataset(MANHATTAN)

    py_daemon = start("py")
    env = dict(clean_env(), SLAMD_NAMESPACE=py_daemon.namespace)
    py = subprocess.run([sys.executable, str(EXAMPLE), str(graph)], capture_output=True,
                        text=True, env=env, timeout=RUN_TIMEOUT_S)
    assert py.returncode == 0, f"{py.stderr}\n--- daemon log\n{py_daemon.tail()}"
    py_out = last_json_line(py.stdout)

    rs_daemon = start("replay")
    rs = subprocess.run([str(binary), "replay", str(graph), "--namespace", rs_daemon.namespace,
                         "--json"], capture_output=True, text=True, env=clean_env(),
                        timeout=RUN_TIMEOUT_S)
    assert rs.returncode == 0, f"{rs.stderr}\n--- daemon log\n{rs_daemon.tail()}"
    rs_out = last_json_line(rs.stdout)

    assert py_out["keyframes"] == rs_out["keyframes"] == 3500
    assert py_out["rejected"] == 0
    relative = abs(py_out["chi2"] - rs_out["chi2"]) / abs(rs_out["chi2"])
    assert relative <= 1e-9, (py_out, rs_out)
    # Manhattan's optimum
    assert abs(py_out["chi2"] - 146.077) < 1e-2
