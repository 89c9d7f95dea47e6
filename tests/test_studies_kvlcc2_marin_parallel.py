"""Study kvlcc2-marin: its fits and replays spread over processes give the serial numbers exactly."""
import json

import pytest

from problems import get_study

TIMINGS = ("seconds", "solve_time_s", "fit_seconds", "workflow_seconds", "created", "fit_json")


def _numbers(value) -> str:
    """A JSON value without its timings and paths (what differs between two runs of the same study),
    as text (NaN compares equal to NaN there)."""
    def strip(v):
        if isinstance(v, dict):
            return {k: strip(x) for k, x in v.items() if k not in TIMINGS}
        return [strip(x) for x in v] if isinstance(v, (list, tuple)) else v
    return json.dumps(strip(value), sort_keys=True, default=repr)


@pytest.mark.slow
@pytest.mark.data
def test_parallel_study_gives_the_serial_numbers(data_dir, tmp_path):
    study = get_study("kvlcc2-marin")
    serial = study.run(tmp_path / "serial", quick=True, workers=1, data_dir=data_dir)
    pooled = study.run(tmp_path / "pooled", quick=True, workers=2, data_dir=data_dir)
    assert _numbers(serial) == _numbers(pooled)
    files = sorted(p.name for p in (tmp_path / "serial").glob("fit*.json"))
    assert "fit.json" in files and len(files) == 2
    for name in files:
        a, b = (json.loads((tmp_path / d / name).read_text()) for d in ("serial", "pooled"))
        assert _numbers(a) == _numbers(b), name
    assert serial["leave_one_run_out"][0]["psi_rmse_deg_fit"] > 0       # numbers, not empty tables
