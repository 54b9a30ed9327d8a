"""Known obstacles (the site's structures as boxes) and a way round them. No rclpy.

A site lists its structures as upright boxes (``site.obstacle_boxes``: centre, size, yaw),
as a survey or a drawing gives them. :func:`route` finds the shortest way from one point
to another that keeps a clearance off every box, in plan: a pillar, a pipe rack or a tank
is gone round, not over (the camera looks ahead, not down). The boxes are grown by the
clearance and the path is the shortest in the visibility graph of their corners (Lozano-
Pérez and Wesley), its altitude changing evenly along it. A box whose height range the
path does not reach is left out; one the start or the goal is already within its
clearance of is grown less (the vehicle may be hovering near the surface it inspects).
"""
import dataclasses
import heapq
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

BOX_FIELDS = ('x', 'y', 'z', 'size_x', 'size_y', 'size_z', 'yaw_deg')
# corners are used a little out from the grown box, so that a path along them is clear
CORNER_OUT_M = 0.01
# the share of its distance to a box that the start or the goal keeps as its clearance there
NEAR_SHARE = 0.9


@dataclasses.dataclass(frozen=True)
class ObstacleBox:
    """An upright box in map: its centre, its full sizes along its own x, y (turned by
    ``yaw_deg`` about map z) and z."""

    centre_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    yaw_deg: float

    @property
    def z_range_m(self) -> tuple[float, float]:
        return (self.centre_m[2] - self.size_m[2] / 2.0, self.centre_m[2] + self.size_m[2] / 2.0)

    def _R(self) -> NDArray[np.float64]:
        """The box's plan axes in map (columns)."""
        c, s = math.cos(math.radians(self.yaw_deg)), math.sin(math.radians(self.yaw_deg))
        return np.array([[c, -s], [s, c]])

    def to_local(self, xy_map: ArrayLike) -> NDArray[np.float64]:
        """Map (x, y) points (..., 2) in the box's own plan axes, from its centre."""
        return (np.asarray(xy_map, dtype=float) - self.centre_m[:2]) @ self._R()

    def to_map(self, xy_local: ArrayLike) -> NDArray[np.float64]:
        """Points (..., 2) in the box's plan axes back in map (:meth:`to_local`'s inverse)."""
        return np.asarray(self.centre_m[:2]) + np.asarray(xy_local, dtype=float) @ self._R().T

    def distance_xy(self, xy_map: ArrayLike) -> float:
        """Distance in plan from a map point to the box (0 inside)."""
        local = np.abs(self.to_local(xy_map)) - np.asarray(self.size_m[:2]) / 2.0
        return float(np.linalg.norm(np.maximum(local, 0.0)))


def boxes_from_flat(values: Sequence[float]) -> list[ObstacleBox]:
    """The boxes of a flat list, ``len(BOX_FIELDS)`` numbers each (``site.obstacle_boxes``);
    ValueError for a length that is not a multiple of it, or a size not above 0."""
    n = len(BOX_FIELDS)
    if len(values) % n:
        raise ValueError(f'{len(values)} numbers are not boxes of {n} ({", ".join(BOX_FIELDS)})')
    boxes = []
    for k in range(0, len(values), n):
        x, y, z, sx, sy, sz, yaw = (float(v) for v in values[k:k + n])
        if not min(sx, sy, sz) > 0.0 or not all(map(math.isfinite, (x, y, z, yaw))):
            raise ValueError(f'box {k // n}: sizes {[sx, sy, sz]} must be more than 0')
        boxes.append(ObstacleBox((x, y, z), (sx, sy, sz), yaw))
    return boxes


def face_views(boxes: Sequence[ObstacleBox], distance_m: float, altitude_m: float,
               seen_from_map: ArrayLike, keep_off_m: float
               ) -> list[tuple[NDArray[np.float64], float]]:
    """(point, yaw) to look at each side face of ``boxes`` from: ``distance_m`` out from its
    middle along its outward normal, at ``altitude_m``, facing it. Faces turned towards
    ``seen_from_map`` (their normal within 45 degrees of the way there: a search from there
    saw them) are left out, and so are points within ``keep_off_m`` of a box."""
    seen_from = np.asarray(seen_from_map, dtype=float)[:2]
    views = []
    for box in boxes:
        yaw = math.radians(box.yaw_deg)
        for k in range(4):
            a = yaw + k * math.pi / 2.0
            n = np.array([math.cos(a), math.sin(a)])
            half = box.size_m[k % 2] / 2.0
            middle = np.asarray(box.centre_m[:2]) + n * half
            to_seen = seen_from - middle
            if n @ to_seen > math.cos(math.radians(45.0)) * np.linalg.norm(to_seen):
                continue
            point = middle + n * distance_m
            if any(b.distance_xy(point) < keep_off_m for b in boxes):
                continue
            views.append((np.array([*point, altitude_m]), math.atan2(-n[1], -n[0])))
    return views


def route(start_map: ArrayLike, goal_map: ArrayLike, boxes: Sequence[ObstacleBox],
          clearance_m: float) -> list[NDArray[np.float64]] | None:
    """The waypoints after ``start_map`` to ``goal_map`` (the goal last; only the goal when
    the straight line is clear) that keep ``clearance_m`` off ``boxes`` in plan; None
    when there is no such way."""
    start, goal = np.asarray(start_map, dtype=float), np.asarray(goal_map, dtype=float)
    z_lo, z_hi = min(start[2], goal[2]) - clearance_m, max(start[2], goal[2]) + clearance_m
    grown = []
    for box in boxes:
        lo, hi = box.z_range_m
        if hi < z_lo or lo > z_hi:
            continue
        near = [box.distance_xy(q[:2]) for q in (start, goal)]
        margin = min([clearance_m] + [NEAR_SHARE * d for d in near if d <= clearance_m])
        if margin > 0.0:
            grown.append((box, np.asarray(box.size_m[:2]) / 2.0 + margin))
    nodes = [start[:2], goal[:2]]
    for box, half in grown:
        corners = np.array([[sx, sy] for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))])
        nodes.extend(box.to_map(corners * (half + CORNER_OUT_M / math.sqrt(2.0))))
    path = _shortest(nodes, grown)
    if path is None:
        return None
    xy = [nodes[k] for k in path]
    lengths = np.cumsum([0.0] + [float(np.linalg.norm(b - a)) for a, b in zip(xy, xy[1:])])
    share = lengths / lengths[-1] if lengths[-1] > 0.0 else np.ones_like(lengths)
    return [np.array([*p, start[2] + f * (goal[2] - start[2])])
            for p, f in zip(xy[1:], share[1:])]


def _shortest(nodes: list[NDArray[np.float64]],
              grown: list[tuple[ObstacleBox, NDArray[np.float64]]]) -> list[int] | None:
    """Node indices of the shortest clear path from node 0 to node 1 (Dijkstra over the
    pairs whose segment meets no grown box), or None."""
    best = {0: 0.0}
    came: dict[int, int] = {}
    queue = [(0.0, 0)]
    done = set()
    while queue:
        d, k = heapq.heappop(queue)
        if k in done:
            continue
        done.add(k)
        if k == 1:
            path = [1]
            while path[-1] != 0:
                path.append(came[path[-1]])
            return path[::-1]
        for j in range(len(nodes)):
            if j in done or not _clear(nodes[k], nodes[j], grown):
                continue
            dj = d + float(np.linalg.norm(nodes[j] - nodes[k]))
            if dj < best.get(j, math.inf):
                best[j], came[j] = dj, k
                heapq.heappush(queue, (dj, j))
    return None


def _clear(a: NDArray[np.float64], b: NDArray[np.float64],
           grown: list[tuple[ObstacleBox, NDArray[np.float64]]]) -> bool:
    """Whether the segment a-b keeps out of the inside of every grown box (slab clipping in
    each box's axes; touching an edge or a corner is clear)."""
    for box, half in grown:
        p, q = box.to_local(a), box.to_local(b)
        d = q - p
        t0, t1 = 0.0, 1.0
        for axis in range(2):
            if abs(d[axis]) < 1e-12:
                if abs(p[axis]) >= half[axis]:
                    t0, t1 = 1.0, 0.0
                    break
                continue
            ta, tb = (-half[axis] - p[axis]) / d[axis], (half[axis] - p[axis]) / d[axis]
            t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
        if t1 - t0 > 1e-9:
            return False
    return True
