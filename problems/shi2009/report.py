"""The paper's own numbers (Tables 1 and 2, the convergence claim) beside casship's, and the departures."""
from __future__ import annotations

import numpy as np

from casship.models import SHI_PARAM_NAMES

from ..kit import Departure, effect, fmt
from .figures import CLAIM_STEP
from .pipeline import POS_STD, PSI_STD, TABLE2, ZIGZAG, pct

#: Shi et al. (2009) Table 1 (units of delta and n not stated; the magnitudes suggest deg and rpm).
PAPER_TABLE1 = {"a1": 1.4347e-4, "a2": -5.4857e-1, "a3": -5.0703e-2, "a4": -7.8174e-6, "a5": -2.4131e-1,
                "a6": 2.0968e-4, "a7": 1.7521e-4, "a8": -3.8163e-5, "a9": 3.8536e-6, "b1": -1.7511e-1,
                "b2": 3.3215e-2, "b3": -2.1508e-4, "b4": -3.125e-2, "c1": -1.8988e-2, "c2": -2.2555e-2,
                "c3": 1.9627e-4}
#: Table 2: turning circle of the target ship ("measured") and of the identified model [m], error [%].
PAPER_TABLE2 = {"advance_m": (790.0, 805.0, 1.90), "transfer_m": (500.0, 525.0, 5.00),
                "tactical_diameter_m": (980.0, 978.0, -0.20)}
ITEM = {"advance_m": "advance", "transfer_m": "transfer", "tactical_diameter_m": "tactical diameter"}


def table2(cases: dict) -> str:
    """Table 2 of the paper beside casship's, for every truth."""
    head = "| item | paper: measured | paper: simulated | paper: error % |"
    rule = "|---|---:|---:|---:|"
    for c in cases.values():
        head += f" {c['label']}: target [m] | augmented EKF [m] (error %) | ML [m] (error %) |"
        rule += "---:|---:|---:|"
    rows = [head, rule]
    for key in TABLE2:
        m, s, e = PAPER_TABLE2[key]
        row = f"| {ITEM[key]} | {m:.0f} | {s:.0f} | {e:+.2f} |"
        for c in cases.values():
            t = c["table2"][key]
            row += (f" {fmt(t['truth'], '.1f')} | {fmt(t['aekf'], '.1f')} ({fmt(t['aekf_error_pct'], '+.1f')}) | "
                    f"{fmt(t['mle'], '.1f')} ({fmt(t['mle_error_pct'], '+.1f')}) |")
        rows.append(row)
    return "\n".join(rows)


def zigzag_table(cases: dict) -> str:
    """20/20 zig-zag indices of the targets and the identified models (the paper shows Figs. 7-8 only)."""
    head, rule = "| item |", "|---|"
    for c in cases.values():
        head += f" {c['label']}: target | augmented EKF | ML |"
        rule += "---:|---:|---:|"
    rows = [head, rule]
    for key in ZIGZAG:
        row = f"| {key} |"
        for c in cases.values():
            z = c["zigzag"][key]
            row += f" {fmt(z['truth'], '.2f')} | {fmt(z['aekf'], '.2f')} | {fmt(z['mle'], '.2f')} |"
        rows.append(row)
    return "\n".join(rows)


def table1(cases: dict) -> str:
    """Table 1 of the paper beside the parameters casship identifies (different ship and units)."""
    head = "| parameter | paper (Table 1) |"
    rule = "|---|---:|"
    for c in cases.values():
        if c["truth_params"] is not None:
            head += f" {c['label']}: truth |"
            rule += "---:|"
        head += f" {c['label']}: augmented EKF | {c['label']}: ML |"
        rule += "---:|---:|"
    rows = [head, rule]
    for k in SHI_PARAM_NAMES:
        row = f"| {k} | {PAPER_TABLE1[k]:.4g} |"
        for c in cases.values():
            if c["truth_params"] is not None:
                row += f" {c['truth_params'][k]:.4g} |"
            row += f" {c['aekf'][k]:.4g} | {c['mle'][k]:.4g} |"
        rows.append(row)
    return "\n".join(rows)


def convergence_table(cases: dict) -> str:
    """Per parameter, the recursive step from which the estimate stays within 10 % of the reference."""
    head, rule = "| parameter |", "|---|"
    for c in cases.values():
        head += f" {c['label']}: settled (own final value) |"
        rule += "---:|"
        if c["truth_params"] is not None:
            head += f" {c['label']}: within 10 % of the truth |"
            rule += "---:|"
    rows = [head, rule]
    show = lambda s: "never" if s is None else str(s)  # noqa: E731
    for k in SHI_PARAM_NAMES:
        row = f"| {k} |"
        for c in cases.values():
            row += f" {show(c['conv'][k]['settled'])} |"
            if c["truth_params"] is not None:
                row += f" {show(c['conv'][k]['to_truth'])} |"
        rows.append(row)
    return "\n".join(rows)


def claim(case: dict) -> dict:
    """The paper's claim ("converged quite well after 200 recursive steps") checked on one case."""
    conv, n = case["conv"], case["steps"]
    settled = [k for k, r in conv.items() if r["settled"] is not None and r["settled"] <= CLAIM_STEP]
    out = {"steps": n, "settled_by_200": len(settled), "settled_in_last_tenth": sum(
        1 for r in conv.values() if r["settled"] is not None and r["settled"] > 0.9 * n)}
    if case["truth_params"] is not None:
        out["within_10pct_of_truth_by_200"] = sum(1 for r in conv.values() if r["to_truth"] is not None
                                                 and r["to_truth"] <= CLAIM_STEP)
        out["within_10pct_of_truth_at_end"] = sum(1 for r in conv.values() if r["to_truth"] is not None)
    return out


def headline(table2_row: dict, conv: dict) -> dict:
    """Headline numbers of one run of the augmented EKF: Table 2 errors and the convergence count."""
    out = {f"{ITEM[k]} error [%]": table2_row[k] for k in TABLE2}
    out["parameters settled by step 200"] = sum(1 for r in conv.values() if r["settled"] is not None
                                                and r["settled"] <= CLAIM_STEP)
    return out


def departures(main: dict, others: dict, mmg: dict | None) -> list[Departure]:
    """The choices the paper leaves open or that this study makes differently, with their effects."""
    eff = lambda key, name: effect(main, others[key], alt_name=name, spec=".3g", relative=False)  # noqa: E731
    mmg_text = ("not run" if mmg is None else
                "with the KVLCC2 MMG model as the truth (its own structure unknown to the identified model): "
                + "; ".join(f"{ITEM[k]} {fmt(mmg['aekf'][k], '+.1f')} % (augmented EKF), {fmt(mmg['mle'][k], '+.1f')} % "
                            "(ML)" for k in TABLE2)
                + (" (n/a: the identified model's manoeuvre diverged)"
                   if any(not np.isfinite(v) for m in mmg.values() for v in m.values()) else ""))
    return [
        Departure("target ship", "a ship of the authors' shiphandling simulator (unnamed); its identified "
                  "Table 1 has no straight-run equilibrium as printed",
                  "the Taylor model itself, fitted by least squares to KVLCC2 MMG manoeuvres (so the truth is "
                  "in the model class); second run: the KVLCC2 MMG model as the truth", mmg_text),
        Departure("input over a step", "the mean of the samples at k and k+1 (Eq. 4, s_m(k))",
                  "the mean, as written", eff("input held over the step", "the input held (zero-order hold)")),
        Departure("initial covariance P(0)", "1e5 I for all 19 states (Sect. 4.2)", "1e5 I, as written",
                  eff("P(0) of u, v, r = R", "P(0) = R for u, v, r (1e5 for the parameters)")),
        Departure("measurement variance R of u, v, r", "not stated",
                  "the RTS smoother's own mean variance of the smoothed u, v, r (no use of the truth)",
                  eff("R from the smoothed-vs-true error", "R from the RMS error of the smoothed velocities against the "
                      "truth (needs the truth)")),
        Departure("process noise of the augmented EKF", "Q not stated", "1e-10 on u, v, r; parameters constant "
                  "(no random walk)", "not measured"),
        Departure("raw data", "shiphandling-simulator records at T = 2 s (noise not stated)",
                  f"positions with {POS_STD:g} m and heading with {np.degrees(PSI_STD):g} deg white noise at T = 2 s",
                  "not measured"),
        Departure("pre-processing constant alpha sigma_a^2 (Eq. 6)", "an 'operation parameter', value not given",
                  "estimated per axis by maximum likelihood through the same Kalman filter", "not measured"),
        Departure("records", "turning circle and zig-zag tests, lengths and order not stated",
                  "20/20 zig-zag then 35 deg turning circle, the estimates and their variances carried from the "
                  "first record to the second", "not measured"),
        Departure("maximum likelihood (ML) through an EKF", "not in the paper (an addition)",
                  "started from the augmented-EKF estimates, process noise estimated too (quick run: sway and "
                  "yaw parameters only)", "reported beside the augmented EKF in every table"),
    ]


def claim_text(cases: dict) -> str:
    """One paragraph: does the paper's convergence claim hold?"""
    parts = []
    for c in cases.values():
        cl = c["claim"]
        txt = (f"{c['label']}: {cl['settled_by_200']} of 16 parameters settle (stay within 10 % of their own final "
               f"value) by step {CLAIM_STEP} of {cl['steps']}; {cl['settled_in_last_tenth']} settle only in the last "
               "tenth of the run")
        if "within_10pct_of_truth_by_200" in cl:
            txt += (f"; {cl['within_10pct_of_truth_by_200']} are within 10 % of the truth by step {CLAIM_STEP} and "
                    f"{cl['within_10pct_of_truth_at_end']} at the end")
        parts.append(txt)
    held = all(c["claim"]["settled_by_200"] == 16 for c in cases.values())
    verdict = "holds" if held else "does not hold for every parameter"
    return (f"The paper's claim, \"the parameters converged quite well after 200 recursive steps\" (Figs. 4-6 show "
            f"a1, b2, c1), {verdict} here. Criterion: the first recursive step from which an estimate stays within "
            "10 % of the reference until the end. " + ". ".join(parts) + ".")


def pct_row(val: dict, key: str) -> dict:
    """Table 2 row for one item: target, identified values and errors in per cent."""
    t_v = val["truth"]["turning"].get(key, np.nan)
    a_v = val["aekf"]["turning"].get(key, np.nan)
    m_v = val["mle"]["turning"].get(key, np.nan)
    return {"truth": t_v, "aekf": a_v, "aekf_error_pct": pct(t_v, a_v), "mle": m_v, "mle_error_pct": pct(t_v, m_v)}
