"""Model library: factories returning :class:`casship.Model` objects, each citing its source."""
from .kinematic import constant_acceleration, double_integrator, sog_cog, sog_cog_latlon, tomera_kinematic
from .kinematic import body_kinematics
from .nomoto import nomoto_first_order, nomoto_second_order
from .registry import get_model, model_names, register
from .kvlcc2 import kvlcc2, kvlcc2_l7
from .mmg import mmg_standard
from .lowspeed import esso_osaka_twin, yoshimura_twin_rudder
from .mariner import mariner
from .otter import otter
from .wind import add_current, add_wind
from .taylor import SHI_DEFAULTS, SHI_PARAM_NAMES, shi_taylor, shi_taylor_preset

register("nomoto1", nomoto_first_order, "first-order Nomoto model (Mariner K, T)")
register("nomoto2", nomoto_second_order, "second-order Nomoto model (Mariner K, T1, T2, T3)")
register("shi-taylor", shi_taylor_preset, "Shi et al. (2009) 16-parameter Taylor response model with kinematics")
register("sog-cog", sog_cog, "five-state SOG/COG/course-rate model, North-East (Fossen & Fossen 2021)")
register("sog-cog-latlon", sog_cog_latlon, "five-state SOG/COG/course-rate model, lat/lon (Fossen & Fossen 2021)")
register("kvlcc2", kvlcc2, "KVLCC2 tanker, full scale 320 m, MMG standard method (Yasukawa & Yoshimura 2015)")
register("kvlcc2-l7", kvlcc2_l7, "KVLCC2 model L7 (7 m, 1/45.7), MMG standard method (Yasukawa & Yoshimura 2015)")
register("mmg-twin-lowspeed", esso_osaka_twin, "Yoshimura low-speed MMG, single propeller + twin rudders "
         "(Esso Osaka 3 m; Koike et al. 2023, Eq. 20-22; propeller/rudder constants assumed)")
register("otter", otter, "Otter USV surge-sway-yaw, two propellers (Fossen, MSS otter.m)")
register("mariner", mariner, "Mariner-class cargo ship, 3 DOF (Chislett & Strom-Tejsen 1965; MSS mariner.m)")
register("tomera-kinematic", tomera_kinematic, "x, y, psi double integrators (Tomera 2011)")
register("body-kinematics", body_kinematics, "3-DOF NED pose driven by body velocities u, v, r (Tomera 2011, Eq. 60)")

__all__ = ["constant_acceleration", "double_integrator", "sog_cog", "sog_cog_latlon", "tomera_kinematic",
           "nomoto_first_order", "nomoto_second_order", "shi_taylor", "SHI_DEFAULTS", "SHI_PARAM_NAMES",
           "get_model", "model_names", "register", "kvlcc2", "kvlcc2_l7", "mmg_standard", "esso_osaka_twin",
           "yoshimura_twin_rudder", "otter", "mariner", "body_kinematics",
           "add_wind", "add_current"]
