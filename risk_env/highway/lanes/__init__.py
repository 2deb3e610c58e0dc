"""The lane predictor for highway-env (:class:`LanePredictor`, ``name = "lane"``): one mode per route
along the road network's lanes, moved by highway-env's own traffic rules.

- :mod:`~risk_env.highway.lanes.predictor`: :class:`LanePredictor` and :class:`LaneMode`;
- :mod:`~risk_env.highway.lanes.routes`: routes through the road network, lanes called on many points;
- :mod:`~risk_env.highway.lanes.table`: every lane as arrays (coordinates, closest lane, the lanes
  highway-env's neighbour search looks at);
- :mod:`~risk_env.highway.lanes.speed`: the speed model (highway-env's IDM and yielding rule);
- :mod:`~risk_env.highway.lanes.weights`: the route weights;
- :mod:`~risk_env.highway.lanes.beliefs`: the beliefs in the lane's frame.
"""

from risk_env.highway.lanes.predictor import LaneMode, LanePredictor

__all__ = ["LaneMode", "LanePredictor"]
