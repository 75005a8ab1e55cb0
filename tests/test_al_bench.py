"""`nearsub al-bench` files: written, read back, summarised again (--from-files), as markdown."""

import subprocess
import sys

import numpy as np

from nearsub.common.learning.albench import summarise
from nearsub.tools.al_bench import markdown_tables, read_outputs, write_outputs


def _result(rng):
    methods, counts, repeats = ["nmmf", "myopic", "hf-us"], list(range(5, 11)), 4
    return {
        "problem": "park",
        "outputs": ["y"],
        "methods": methods,
        "repeats": repeats,
        "hf_samples": 10,
        "seed": 0,
        "jobs": 1,
        "settings": {},
        "test_points": 10,
        "n_hf": counts,
        "mape": {m: rng.uniform(0.1, 2.0, (repeats, len(counts), 1)) for m in methods},
        "reference": {"counts": [10], "mape": {m: rng.uniform(0.1, 2.0, (repeats, 1, 1)) for m in methods}},
        "wall_seconds": 1.0,
        "task_seconds_per_method": {m: 0.1 for m in methods},
    }


def test_files_read_back_to_the_same_result_and_summary(tmp_path):
    result = _result(np.random.default_rng(3))
    summary = summarise(result)
    write_outputs(result, summary, tmp_path)
    back = read_outputs("park", tmp_path)
    for key in ("mape", "reference"):
        mapes = back[key] if key == "mape" else back[key]["mape"]
        want = result[key] if key == "mape" else result[key]["mape"]
        assert all(np.array_equal(mapes[m], want[m]) for m in result["methods"])
    assert summarise(back) == summary
    pairs = summary["outputs"]["y"]["pairs"]
    a, b = result["mape"]["nmmf"][:, :, 0], result["mape"]["myopic"][:, :, 0]
    assert pairs["nmmf<myopic"] == np.mean(a < b, axis=0).tolist()
    assert set(pairs) == {"nmmf<myopic", "nmmf<hf-us", "myopic<hf-us"}
    table = markdown_tables(back, summary)
    med = summary["outputs"]["y"]["reference_gp"]["stats"]["nmmf"]["median"][0]
    assert "| 10, reference GP | " + f"{med:.3g} (" in table and "nmmf < myopic" in table


def test_from_files_without_files_is_one_line_and_exit_2(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "nearsub", "al-bench", "park", "--from-files", "-o", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.startswith("nearsub al-bench: --from-files: no ") and len(done.stderr.splitlines()) == 1
