"""The nested choice of the kvlcc2-marin study (problems/kvlcc2_marin/choice.py): its inner folds
and its rule, with the fits and replays replaced by known numbers (no data needed)."""
from types import SimpleNamespace

import pytest

from problems.kvlcc2_marin import choice


def test_inner_groups_deal_sorted_names_round_robin():
    assert choice.inner_groups(["c", "a", "e", "b", "d"]) == [["a", "d"], ["b", "e"], ["c"]]
    assert choice.inner_groups(["b", "a"]) == [["a"], ["b"]]
    groups = choice.inner_groups([f"run{i:02d}" for i in range(16)])
    assert sorted(n for g in groups for n in g) == [f"run{i:02d}" for i in range(16)]
    assert [len(g) for g in groups] == [6, 5, 5]


def _rigged(monkeypatch, captive_rmse, joint_rmse):
    """choose() with the captive-only replay and the inner joint fits' replays set per run."""
    cap = SimpleNamespace(params=lambda facility=None: {"who": "captive"})
    monkeypatch.setattr(choice, "captive_only", lambda captive: cap)
    monkeypatch.setattr(choice, "per_run", lambda what, run, make: make())
    fitted = []

    def fit_fold(train, smoothed, curve, **kw):
        fitted.append(sorted(r.name for r in train))
        return SimpleNamespace(params=lambda facility=None: {"who": "joint"})

    monkeypatch.setattr(choice, "fit_fold", fit_fold)
    monkeypatch.setattr(choice, "heading_rmse",
                        lambda run, p: (captive_rmse if p["who"] == "captive" else joint_rmse)[run.name])
    return fitted


def _runs(*names):
    return [SimpleNamespace(name=n, facility="X") for n in names]


def test_the_joint_fit_is_chosen_only_when_its_inner_score_is_lower(monkeypatch):
    runs = _runs("a", "b", "c", "d")
    fitted = _rigged(monkeypatch, {"a": 5, "b": 5, "c": 5, "d": 5}, {"a": 1, "b": 9, "c": 4, "d": 4})
    out = choice.choose(runs, {}, None, dt=2.0, max_free=3, captive=("folder", None))
    assert out["choice"] == "joint" and out["scores"] == {"captive-only": 5.0, "joint": 4.5}
    # every inner fit leaves out its own group, and no run is scored by a fit that saw it
    assert fitted == [["b", "c"], ["a", "c", "d"], ["a", "b", "d"]]
    _rigged(monkeypatch, {"a": 4, "b": 4, "c": 4, "d": 4}, {"a": 4, "b": 4, "c": 4, "d": 4})
    tie = choice.choose(runs, {}, None, dt=2.0, max_free=3, captive=("folder", None))
    assert tie["choice"] == "captive-only", "a tie keeps the model that spends no free-running evidence"


def test_one_training_run_keeps_the_captive_only_model(monkeypatch):
    fitted = _rigged(monkeypatch, {"a": 9}, {"a": 1})
    out = choice.choose(_runs("a"), {}, None, dt=2.0, max_free=3, captive=("folder", None))
    assert out["choice"] == "captive-only" and not fitted and out["groups"] == []


def test_fold_families_select_the_folds_and_unknown_ones_are_named():
    from casship.errors import InputError
    from problems import kvlcc2_marin as marin

    runs = [SimpleNamespace(name=n, facility=f, kind="turning") for n, f in (("a", "X"), ("b", "Y"), ("c", "X"))]
    assert marin.fold_specs(runs, families=marin.FIT_FILE_FAMILIES) == [("run", n, (n,)) for n in "abc"]
    facility = marin.fold_specs(runs, families=("facility",))
    assert facility == [("facility", "X", ("a", "c")), ("facility", "Y", ("b",))]
    # the regime of every run is the same here, so that family has no fold; the default runs every family
    assert [s[0] for s in marin.fold_specs(runs, families=("run", "regime", "facility"))] == ["run"] * 3 + ["facility"] * 2
    with pytest.raises(InputError, match="'directions'"):
        marin.fold_specs(runs, families=("run", "directions"))
