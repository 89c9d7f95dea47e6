"""The benchmark command: discovery, skipped rows for missing peers, error rows, table and JSON."""
import json
import sys
import types

import pytest

import benchmarks
from benchmarks import __main__ as runner


def fake_module(monkeypatch, name, main=None, import_error=None):
    full = f"benchmarks.{name}"
    if import_error:
        real_import = runner.importlib.import_module

        def importer(mod, *args):
            if mod == full:
                raise ImportError(f"No module named {import_error!r}", name=import_error)
            return real_import(mod, *args)

        monkeypatch.setattr(runner.importlib, "import_module", importer)
    else:
        module = types.ModuleType(full)
        module.main = main
        monkeypatch.setitem(sys.modules, full, module)


def test_rows_skips_and_errors(monkeypatch):
    monkeypatch.setattr(runner, "discover", lambda only=None: ["bench_ok", "bench_peerless", "bench_broken"])
    fake_module(monkeypatch, "bench_ok", main=lambda quick=False: [
        benchmarks.row("thing", 0.5, "peer", 1.5, "max abs diff 1e-12")])
    fake_module(monkeypatch, "bench_peerless", import_error="filterpy")

    def broken(quick=False):
        raise ZeroDivisionError("oops")

    fake_module(monkeypatch, "bench_broken", main=broken)
    rows = runner.run_all(quick=True, verbose=False)
    ok, skipped, error = rows
    assert ok["ratio"] == pytest.approx(3.0) and ok["module"] == "bench_ok"
    assert skipped["peer_s"] is None and "filterpy" in skipped["skipped"] and "bench" in skipped["skipped"]
    assert error["error"] == "ZeroDivisionError: oops"
    table = benchmarks.format_table(rows)
    assert "| thing | 0.5 | peer | 1.5 | 3 | max abs diff 1e-12 |" in table
    assert "skipped: cannot import filterpy" in table and "error: ZeroDivisionError" in table


def test_median_time_and_row():
    calls = []
    assert benchmarks.median_time(lambda: calls.append(1), repeat=3, warmup=2) >= 0.0
    assert len(calls) == 5
    assert benchmarks.row("b", 0.0, "p", 1.0, "")["ratio"] is None
    with pytest.raises(ValueError, match="repeat"):
        benchmarks.median_time(lambda: None, repeat=0)


def test_command_writes_json(tmp_path, capsys):
    out = tmp_path / "bench.json"
    from casship.cli import main

    assert main(["bench", "--quick", "--only", "simulate", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["quick"] and result["machine"]["casadi"]
    names = {r["peer"] for r in result["rows"]}
    assert "scipy solve_ivp RK45 (NumPy rhs)" in names
    assert all(r["ratio"] > 0 for r in result["rows"])
    assert "| benchmark | casship [s]" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        runner.main(["--only", "no_such_topic"])


def test_markdown_results_section_is_replaced_in_place(tmp_path):
    page = tmp_path / "benchmarks.md"
    page.write_text(f"# B\n\nintro\n\n{runner.START}\nold table\n{runner.END}\n\nnotes stay\n")
    info = runner.machine_info()
    rows = [benchmarks.row("x", 1.0, "p", 2.0, "ok")]
    runner.write_markdown(page, runner.results_markdown(rows, info, False, "python -m benchmarks"))
    text = page.read_text()
    assert "old table" not in text and "| x | 1 | p | 2 | 2 | ok |" in text
    assert text.startswith("# B\n\nintro") and text.rstrip().endswith("notes stay")
    assert info["cpu"] in text and f"CasADi {info['casadi']}" in text


def test_compare_interleaves_and_reports_the_ratio_spread():
    order = []
    clock = iter(range(100)).__next__                # each reading one tick later

    def peer():
        order.append("peer")
        for _ in range(2):                            # the peer reads the clock twice more: 3 ticks
            clock()

    def fast():
        order.append("casship")

    t = benchmarks.compare(fast, peer, repeat=3, warmup=1, clock=lambda: float(clock()))
    assert order == ["peer", "casship"] * 4
    assert t["peer_s"] == 3.0 and t["casship_s"] == 1.0
    assert t["ratio"] == t["ratio_min"] == t["ratio_max"] == 3.0 and t["repeats"] == 3
    r = benchmarks.compared_row("b", t, "p", "same", target="ekf_batch")
    assert r["ratio"] == 3.0 and r["ratio_min"] == 3.0 and r["target"] == "ekf_batch"
    assert "| b | 1 | p | 3 | 3 [3-3] | same |" in benchmarks.format_table([r])


def test_targets_table_says_met_missed_and_not_measured():
    rows = [dict(benchmarks.row("EKF thing", 1.0, "filterpy", 60.0, "ok", target="ekf_batch"), ratio_min=55.0,
                 ratio_max=65.0),
            benchmarks.row("UKF thing", 1.0, "filterpy", 100.0, "ok", target="ukf_batch"),
            dict(benchmarks.row("EnKF thing", 1.0, "filterpy", 50.0, "ok", target="enkf_batch"), first_call_s=9.0)]
    table = benchmarks.format_targets(rows)
    lines = {line.split(" | ")[0].lstrip("| "): line for line in table.splitlines()[2:]}
    assert len(lines) == len(benchmarks.TARGETS)
    assert "60x [55-65]" in lines["EKF batch, compiled, vs filterpy EKF"] and lines["EKF batch, compiled, vs filterpy EKF"].endswith("| yes |")
    assert lines["UKF batch, compiled, vs filterpy UKF"].endswith("| NO |")
    enkf = lines["EnKF (100 members) batch, compiled, vs filterpy EnKF"]
    assert "first call 9.0 s" in enkf and enkf.endswith("| NO |")      # ratio met, first call not
    assert "not measured in this run" in lines["MHE N=20, RTI, vs do-mpc"]
