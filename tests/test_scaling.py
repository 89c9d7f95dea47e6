"""Froude similarity of ship particulars (casship.models.scaling)."""
import math

import pytest

from casship.models import kvlcc2, kvlcc2_l7
from casship.models.kvlcc2 import KVLCC2_COMMON, KVLCC2_FULL, SCALE_L7
from casship.models.scaling import froude_rate, froude_scale, froude_speed


def test_lengths_areas_volumes_and_coefficients():
    lam = 320.0 / 7.0
    small = froude_scale({**KVLCC2_COMMON, **KVLCC2_FULL, "source": "x"}, lam)
    assert small["L_pp"] == pytest.approx(7.0, rel=1e-12)
    assert small["A_R"] == pytest.approx(112.5 / lam**2, rel=1e-12)
    assert small["nabla"] == pytest.approx(312600.0 / lam**3, rel=1e-12)
    for k in ("R_0_dash", "Y_v_dash", "rho", "k_zz", "t_P"):
        assert small[k] == KVLCC2_COMMON[k]
    assert small["source"] == "x"
    # the published model-scale particulars are the full-scale ones Froude-scaled (within their rounding)
    l7 = kvlcc2_l7().param_dict()
    for k in ("B", "d", "D_p", "H_R", "A_R", "nabla"):
        assert froude_scale(KVLCC2_FULL, SCALE_L7)[k] == pytest.approx(l7[k], rel=0.02), k


def test_scaled_model_keeps_the_froude_number_and_nondimensional_dynamics():
    """A Froude-scaled copy of KVLCC2 at the scaled speed and propeller rate has accelerations
    scaled by 1 (linear) and sqrt-scaled rates, i.e. the same motion in non-dimensional time."""
    import numpy as np
    from casship.models.mmg import mmg_standard

    lam = 320.0 / 13.75
    full = kvlcc2()
    small = mmg_standard(froude_scale({**KVLCC2_COMMON, **KVLCC2_FULL}, lam), name="small")
    U, n, r = full.vessel.U0, 1.53, 0.002
    xf = full.states(u=U, v=-0.2, r=r)
    xs = small.states(u=froude_speed(U, lam), v=froude_speed(-0.2, lam), r=froude_rate(r, lam))
    df = np.ravel(full.f(xf, full.inputs(delta=0.2, n=n), full.params(), np.zeros(full.nw)))
    ds = np.ravel(small.f(xs, small.inputs(delta=0.2, n=froude_rate(n, lam)), small.params(), np.zeros(small.nw)))
    i_u, i_r = full.state_names.index("u"), full.state_names.index("r")
    assert ds[i_u] == pytest.approx(df[i_u], rel=1e-9)                      # du/dt: g-scaled, same
    assert ds[i_r] == pytest.approx(df[i_r] * lam, rel=1e-9)                # dr/dt: 1/time^2 scales by lam


def test_bad_scale():
    with pytest.raises(ValueError, match="scale ratio"):
        froude_scale({"L_pp": 1.0}, 0.0)
    assert froude_speed(4.0, 4.0) == 2.0 and froude_rate(1.0, 4.0) == 2.0
    assert math.isclose(froude_rate(froude_speed(1.0, 9.0), 9.0), 1.0)
