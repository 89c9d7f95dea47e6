"""A parameter file written from values that come from elsewhere (another facility's captive tests):
it replays like a fit file, on the same model variant, with its covariance bit for bit; bad values
and foreign names are refused by name."""
import json

import numpy as np
import pytest

from casship.errors import InputError
from casship.identify import ParameterBelief, read_fit_file, write_params_file
from casship.models import kvlcc2, nomoto_first_order

COV = [[1.2345678901234567e-4, 3.3333333333333335e-5], [3.3333333333333335e-5, 4.000000000000001e-4]]


def test_values_and_covariance_round_trip_on_the_same_variant(tmp_path):
    m = kvlcc2(asymmetry=True, smooth=True)
    values = {"N_r_dash": -0.03293, "Y_r_dash": 0.1311}
    belief = ParameterBelief.from_values(list(values), list(values.values()), COV, "captive tests", kind="robust")
    path = write_params_file(tmp_path / "p.json", m, values, belief, {"candidate": "captive-only"})
    back = read_fit_file(path)
    assert back.model.meta["options"] == {"asymmetry": True, "smooth": True}
    got = dict(zip(back.model.param_names, back.params))
    nominal = m.param_dict()
    for name in m.param_names:
        assert got[name] == (values[name] if name in values else nominal[name]), name
    assert np.array_equal(back.uncertainty.cov, np.asarray(COV))
    assert json.loads(path.read_text())["candidate"] == "captive-only"
    # the file names its variant: the symmetric model is refused
    with pytest.raises(InputError, match="parameter set"):
        read_fit_file(path, kvlcc2())


def test_bad_values_are_refused_by_name(tmp_path):
    m = nomoto_first_order()
    with pytest.raises(InputError, match="'N_r_dash'"):
        write_params_file(tmp_path / "a.json", m, {"N_r_dash": 1.0})
    with pytest.raises(InputError, match="'K'"):
        write_params_file(tmp_path / "b.json", m, {"K": float("nan")})
    other = ParameterBelief.from_values(["K"], [0.5], [[1e-4]], "elsewhere")
    with pytest.raises(InputError, match="'K'"):
        write_params_file(tmp_path / "c.json", m, {"K": 0.4}, other)
    assert not any(tmp_path.iterdir())
