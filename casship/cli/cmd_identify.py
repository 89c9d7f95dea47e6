"""``casship identify DATA... --model NAME --free P1,P2``: fit model parameters to records.

Examples::

    casship identify run1.csv run2.csv --model nomoto1 --free K,T --R psi=1e-4 --out fit.json
    casship identify ../shared/data/kvlcc2_marin_free/MARIN_FREE_KVLCC2_zz_10_m.dat --model kvlcc2 \\
        --free N_r_dash,Y_v_dash --measured u,v,r,psi --decimate 20 --out fit.json --plot fit.png
    casship simulate --model kvlcc2 --params fit.json --inputs ../shared/data/kvlcc2_marin_free/MARIN_FREE_KVLCC2_zz_-20_m.dat

Records are CSV files with a header row (columns named like the model's inputs and outputs, SI
units, radians) or MARIN ``.dat`` files (read by :func:`casship.io.read_marin`, rudder sign flipped
to the MMG convention). ``--method mle`` (default) maximises the likelihood through an EKF;
``--method oe`` minimises the simulated output error.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def register(sub) -> None:
    p = sub.add_parser("identify", help="fit model parameters to records (maximum likelihood or output error)",
                       description="Estimate named parameters of a registered model from one or more records, "
                                   "with standard errors, correlations and identifiability warnings.")
    p.add_argument("data", nargs="+", help="records: CSV with a header row, or MARIN .dat")
    p.add_argument("--model", required=True, help="registered model name (see 'casship simulate --list')")
    p.add_argument("--free", required=True, help="comma-separated parameter names to estimate")
    p.add_argument("--out", default="fit.json", help="JSON file for the fit (default fit.json)")
    p.add_argument("--method", default="mle", choices=("mle", "oe"),
                   help="mle: likelihood through an EKF (default); oe: output error (simulation)")
    p.add_argument("--measured", default=None, help="outputs to use a,b,... (default: outputs present in the data)")
    p.add_argument("--R", default=None, help="measurement variances name=value,... (mle; default: estimated)")
    p.add_argument("--Q", default=None, help="process-noise variances: scalar or name=value,... (mle; default 1e-8)")
    p.add_argument("--estimate-noise", dest="estimate_noise", default=None,
                   help="noise variances to estimate: Q, R or Q,R (mle; R is estimated when --R is absent)")
    p.add_argument("--sigma", default=None, help="output standard deviations name=value,... (oe weights)")
    p.add_argument("--guess", default=None, help="starting values name=value,... (default: model values)")
    p.add_argument("--params", default=None, help='JSON {"params": {...}} with the fixed parameter values')
    p.add_argument("--estimate-x0", dest="estimate_x0", default=None,
                   help="states whose initial values are estimated per record a,b,...")
    p.add_argument("--decimate", type=int, default=1, help="keep every k-th sample (default 1)")
    p.add_argument("--shooting", default="single", choices=("single", "multiple"), help="oe: shooting")
    p.add_argument("--hessian", default="fisher", choices=("fisher", "exact", "limited-memory"),
                   help="curvature used by IPOPT (mle; default fisher)")
    p.add_argument("--plot", default=None, help="PNG of measured vs predicted outputs")
    p.add_argument("--json", action="store_true", help="print the fit as JSON instead of a table")
    p.set_defaults(func=run)


def _pairs(text: str | None, what: str) -> dict[str, float]:
    out = {}
    if not text:
        return out
    for item in text.split(","):
        if "=" not in item:
            raise ValueError(f"{what}: expected name=value, got {item!r}")
        k, v = item.split("=", 1)
        try:
            out[k.strip()] = float(v)
        except ValueError:
            raise ValueError(f"{what}: value of {k.strip()!r} is not a number ({v!r})") from None
    return out


def _names(text: str | None) -> list[str]:
    return [s.strip() for s in text.split(",") if s.strip()] if text else []


def load_record(path):
    """A CSV (header row) or MARIN ``.dat`` record as a :class:`casship.Dataset`."""
    from ..data import Dataset
    from ..io.marin import read_marin

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"record {path} does not exist")
    if path.suffix.lower() == ".dat":
        from ..angles import wrap

        data = read_marin(path)
        data = data.with_columns(psi=wrap(data["psi"]))   # the files hold a continuous heading
    else:
        data = Dataset.from_csv(path)
    data.meta.setdefault("name", path.name)
    return data


def _decimate(data, k: int):
    if k < 1:
        raise ValueError(f"--decimate must be >= 1, got {k}")
    if k == 1:
        return data
    from ..data import Dataset

    idx = np.arange(0, len(data), k)
    return Dataset(data.t[idx], {n: data[n][idx] for n in data.names}, data.units, data.meta)


def _noise_start(data, names) -> dict[str, float]:
    """Starting measurement variances from first differences (half their variance), floored."""
    out = {}
    for n in names:
        y = np.concatenate([d[n] for d in data])
        dy = np.diff(y[np.isfinite(y)])
        out[n] = max(0.5 * float(np.var(dy)) if dy.size else 1.0, 1e-10)
    return out


def run(args) -> int:
    from ..discretize import discretize
    from ..estimators import EKF
    from ..identify import MLEProblem, OutputErrorProblem
    from ..models import get_model
    from .cmd_simulate import _load_params

    model = get_model(args.model)
    records = [_decimate(load_record(p), args.decimate) for p in args.data]
    free = _names(args.free)
    if not free:
        raise ValueError("--free: give at least one parameter name")
    params = _load_params(args.params) if args.params else None
    guess = _pairs(args.guess, "--guess")
    measured = _names(args.measured) or [n for n in model.output_names if all(n in d for d in records)]
    if not measured:
        raise ValueError(f"no output of {model.name!r} {list(model.output_names)} is a column of every record")
    x0_states = _names(args.estimate_x0)
    if args.method == "oe":
        sigma = _pairs(args.sigma, "--sigma")
        prob = OutputErrorProblem(model, records, free, measured=measured, sigma=sigma or None, params=params,
                                  estimate_x0=x0_states, shooting=args.shooting)
        fit = prob.solve(guess=guess)
    else:
        dt = float(np.median(np.diff(records[0].t)))
        R = _pairs(args.R, "--R")
        unknown = set(R) - set(measured)
        if unknown:
            raise ValueError(f"--R names {sorted(unknown)} not among measured outputs {measured}")
        start = _noise_start(records, [n for n in measured if n not in R])
        R_all = {n: R.get(n, start.get(n)) for n in measured}
        estimate = set(_names(args.estimate_noise))
        bad = estimate - {"Q", "R"}
        if bad:
            raise ValueError(f"--estimate-noise: unknown {sorted(bad)}; use Q, R or Q,R")
        noise = {}
        if "R" in estimate:
            noise["R"] = True
        elif len(R) < len(measured):
            noise["R"] = [n for n in measured if n not in R]
        if "Q" in estimate:
            noise["Q"] = True
        try:
            Q = float(args.Q) if args.Q else 1e-8
        except ValueError:
            Q = _pairs(args.Q, "--Q")
        ekf = EKF(discretize(model, dt), Q, R_all, measured=measured)
        prob = MLEProblem(ekf, records, free, params=params, noise=noise, estimate_x0=x0_states)
        fit = prob.solve(guess=guess, hessian=args.hessian)
    fit.to_json(args.out)
    if args.plot:
        fit.plot(args.plot)
    if args.json:
        print(json.dumps(fit.to_dict()))
    else:
        print(fit.summary())
        print(f"fit written to {args.out}")
    return 0
