"""RiskCrossing meets highway-env: its graphics, its worlds and its controlled vehicle.

- :mod:`risk_env.highway.graphics`: ``RiskCrossing-v0`` drawn with highway-env's road and vehicle
  graphics (``renderer="highway"``), and our overlays (truncation boxes, Monte Carlo draws, an
  MPC plan) on any highway-env scene;
- :class:`RiskCostWrapper`: ``info["risk"]``, ``info["cost"]`` and ``info["risk_violation"]`` for
  any highway-env environment, from :func:`risk_env.predict` and :mod:`risk_env.risk.estimators`;
- :class:`IntersectionAdapter`: our MPC agents drive highway-env's controlled vehicle on
  ``intersection-v1`` with continuous actions; :class:`IDMEgo` is highway-env's own IDM driver for
  comparison;
- :class:`LanePredictor`: a prediction that follows highway-env's lanes (one mode per route, the
  speed from highway-env's own traffic rules), :mod:`risk_env.highway.lanes`.

highway-env is optional (``pip install 'riskcrossing[render]'``); ``import risk_env`` never needs
it, this subpackage does.
"""

from risk_env.highway.common import require_highway_env

require_highway_env()

from risk_env.highway.adapter import (  # noqa: E402
    INTERSECTION_CONFIG,
    IDMEgo,
    IntersectionAdapter,
    make_intersection_env,
)
from risk_env.highway.common import highway_scenario, policy_period, vehicle_measurement  # noqa: E402
from risk_env.highway.lanes.predictor import LaneMode, LanePredictor  # noqa: E402
from risk_env.highway.route import RoutePath  # noqa: E402
from risk_env.highway.wrapper import RiskCostWrapper  # noqa: E402

__all__ = [
    "INTERSECTION_CONFIG",
    "IDMEgo",
    "IntersectionAdapter",
    "LaneMode",
    "LanePredictor",
    "RiskCostWrapper",
    "RoutePath",
    "highway_scenario",
    "make_intersection_env",
    "policy_period",
    "require_highway_env",
    "vehicle_measurement",
]
