"""Domain-randomised, automatically labelled detector images rendered with the plant's world.

Each world (wall, ground, 1-5 inspection objects, plain distractor panels) is built with
``uav_tilt_sim.world.build_world`` and photographed by the plant's camera model from
``IMAGES_PER_WORLD`` random poses: 0.4-5 m (log-uniform; the mission's ranges) from a point
on the wall, up to 45 deg off its normal, with roll jitter and, sometimes, an occluding bar
in front. Lighting, exposure, blur and sensor noise are drawn per image. In
``VEHICLE_PROB`` of the images the camera is the vehicle's own eye-in-hand camera, so its
tool (rod and tip) is in view as in flight, in front of the target at contact. Boxes are
the tight bounds of each object's pixels in the simulator's segmentation, so occlusion and
truncation are exact. An object in view but less visible than the labelling rule asks
(``MIN_VISIBLE_PX``, ``MIN_VISIBLE_FRACTION``) is written to ``ignore/`` instead of
``labels/``: a region where a detection is neither right nor wrong (COCO's crowd regions,
KITTI's "don't care").

With ``scenes='structures'`` each world is instead one of the campaign's structure kinds
other than a wall (``uav_tilt_sim.randomise_structures``: a corner, a pillar, pipes, a tank,
a mesh), its target and up to three more objects of random classes on the same surface, and
the camera looks along each object's own surface normal: a scene set to score the detector
on curved and cornered surfaces against the flat wall.

Splits (``SPLITS``): ``train`` and ``heldout`` draw from disjoint RNG streams (object,
wall and ground textures never repeat), disjoint wall texture families and disjoint
lighting ranges; ``meta.json`` records them. Output is YOLO text format (``yolo_data``).
Image k of a set depends only on (seed, split, k // IMAGES_PER_WORLD), not on ``jobs``.
"""

import dataclasses
import functools
import json
import multiprocessing
import os
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence, TypeVar

import cv2
import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from uav_tilt_common.config import ConfigError
from uav_tilt_common.pose import Pose
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_sim import textures
from uav_tilt_sim.bullet import pybullet as p
from uav_tilt_sim.camera import CameraConfig, Lighting, Renderer, make_renderer
from uav_tilt_sim.randomise_structures import STRUCTURE_KINDS, structure_draw
from uav_tilt_sim.scenario import ObjectConfig, Scenario, WallConfig, check_scenario
from uav_tilt_sim.vehicle_body import create_vehicle
from uav_tilt_sim.visuals import BOX, Scene, Visual, apply_texture, create_static_body
from uav_tilt_sim.world import WorldInfo, build_world

T = TypeVar('T')
R_ = TypeVar('R_')
# one world's job for render_world: (out, seed, split, world, image indices, renderer,
# (min, max) camera distance in m, scenes)
Job = tuple[str, int, str, int, range, str, tuple[float, float], str]
# YOLO rows [class, cx, cy, w, h] (normalised)
LabelRows = list[list[float]]

CLASSES = textures.OBJECT_CLASSES
IMAGES_PER_WORLD = 6
MIN_VISIBLE_PX = 30
# An object less visible than this (occluded or cut by the image border) is not labelled:
# too little of it is left to tell its class.
MIN_VISIBLE_FRACTION = 0.35
MAX_VIEW_ANGLE_DEG = 45.0
DISTANCE_M = (0.4, 5.0)   # the mission's ranges: a 0.2 m plate spans 11-140 px
PATCH_UV_M = ((-2.0, 0.3), (2.0, 3.1))   # where objects and panels go on the wall (u, v)
OCCLUDER_PROB = 0.3
VEHICLE_PROB = 0.5
SCENES = ('wall', 'structures')
STRUCTURE_SCENE_KINDS = tuple(k for k in STRUCTURE_KINDS
                              if k not in ('wall', 'pillar_between'))
# the more objects of a structure scene: the target's place moved along the surface by
# this many metres (up the wall or face, along the pipe's axis, up the mesh)
EXTRA_OBJECT_SHIFTS_M = (-0.7, -0.35, 0.35, 0.7)


@dataclasses.dataclass(frozen=True)
class SplitSpec:
    """What a split may draw: its RNG stream, wall families and lighting ranges."""

    stream: int
    wall_families: tuple[str, ...]
    ambient: tuple[float, float]
    diffuse: tuple[float, float]
    light_tint: tuple[float, float]          # per-channel light colour range
    light_azimuth_deg: tuple[float, float]   # |azimuth| of the light about the wall normal


SPLITS = {
    'train': SplitSpec(0, ('concrete', 'bricks', 'stripes'), (0.45, 0.75), (0.25, 0.55),
                       (0.85, 1.0), (0.0, 60.0)),
    'heldout': SplitSpec(1, ('painted_panels',), (0.35, 0.45), (0.55, 0.65),
                         (0.72, 0.85), (60.0, 85.0)),
}


def random_scenario(rng: np.random.Generator) -> Scenario:
    """A wall with 1-5 non-overlapping inspection objects of random classes."""
    wall = WallConfig(position_m=[3.0, 0.0], yaw_deg=float(rng.uniform(-180, 180)),
                      inclination_deg=float(rng.uniform(-20, 20)),
                      width_m=float(rng.uniform(6, 12)), height_m=float(rng.uniform(4, 6)))
    objects: list[ObjectConfig] = []
    for _ in range(int(rng.integers(1, 6))):
        u, v = rng.uniform(*PATCH_UV_M)
        if all(max(abs(u - o.u_m), abs(v - o.v_m)) > 0.3 for o in objects):
            cls = CLASSES[int(rng.integers(len(CLASSES)))]
            objects.append(ObjectConfig(cls=cls, u_m=float(u), v_m=float(v)))
    return Scenario(wall=wall, objects=objects)


def _box_body(scene: Scene, centre: np.ndarray, R: np.ndarray, half_extents: Sequence[float],
              rng: np.random.Generator) -> int:
    """A plain-coloured static box oriented by R (map)."""
    box = Visual(BOX, tuple(half_extents), tuple(rng.uniform(0, 1, 3)) + (1.0,))
    return create_static_body(scene.client, scene, box, centre,
                              Rotation.from_matrix(R).as_quat())


def random_structure_scenario(rng: np.random.Generator) -> Scenario:
    """A campaign's structure world of a kind other than a wall, its target of a random
    class and up to three more objects on the same surface (where they fit on it)."""
    kind = STRUCTURE_SCENE_KINDS[int(rng.integers(len(STRUCTURE_SCENE_KINDS)))]
    scenario, _, _ = structure_draw(int(rng.integers(2**31)), kind)
    first = scenario.objects[0]
    cls = CLASSES[int(rng.integers(len(CLASSES)))]
    objects = [dataclasses.replace(first, cls=cls, target=cls in textures.POI_UV)]
    shifts = rng.permutation(EXTRA_OBJECT_SHIFTS_M)[:int(rng.integers(0, 4))]
    for shift in shifts:
        moved = dataclasses.replace(first, target=False, id='',
                                    cls=CLASSES[int(rng.integers(len(CLASSES)))],
                                    **_shifted_place(scenario, first, float(shift)))
        try:
            check_scenario(dataclasses.replace(scenario, objects=[*objects, moved]))
        except ConfigError:     # off its surface, or on another object
            continue
        objects.append(moved)
    return dataclasses.replace(scenario, objects=objects)


def _shifted_place(scenario: Scenario, obj: ObjectConfig, shift_m: float) -> dict[str, Any]:
    """``obj``'s surface coordinates moved by ``shift_m`` along its structure's surface."""
    kind = next(s.kind for s in scenario.structures if s.id == obj.on)
    if kind == 'mesh':
        return {'point_m': [obj.point_m[0], obj.point_m[1], obj.point_m[2] + shift_m]}
    if kind == 'cylinder':
        return {'axial_m': obj.axial_m + shift_m}
    return {'v_m': obj.v_m + shift_m}


def build_random_world(scene: Scene, rng: np.random.Generator, spec: SplitSpec,
                       scenes: str = 'wall') -> WorldInfo:
    """Build a random world (``scenes``: a wall, or a structure) whose surfaces' textures
    are of one of ``spec``'s families."""
    if scenes == 'structures':
        return _build_structure_world(scene, rng, spec)
    scenario = random_scenario(rng)
    client = scene.client
    info = build_world(client, scenario, texture_rng=rng, scene=scene)
    family = spec.wall_families[int(rng.integers(len(spec.wall_families)))]
    face = dataclasses.replace(info.wall_visual,
                               texture=textures.wall_texture(rng, family=family))
    apply_texture(client, info.wall_body, face)
    scene.add(info.wall_body, -1, [face], static=True)
    R = info.R_map_wall
    for _ in range(int(rng.integers(0, 4))):     # distractors: object-sized plain panels
        u, v = rng.uniform(*PATCH_UV_M)
        if all(max(abs(u - o.u_m), abs(v - o.v_m)) > 0.3 for o in scenario.objects):
            centre = info.wall_origin_map + R @ [u, v, 0.004]
            _box_body(scene, centre, R, [*rng.uniform(0.05, 0.15, 2), 0.003], rng)
    return info


def _build_structure_world(scene: Scene, rng: np.random.Generator, spec: SplitSpec
                           ) -> WorldInfo:
    info = build_world(scene.client, random_structure_scenario(rng), texture_rng=rng,
                       scene=scene)
    for s in info.structures:
        family = spec.wall_families[int(rng.integers(len(spec.wall_families)))]
        face = dataclasses.replace(s.visual, texture=textures.wall_texture(rng, family=family))
        apply_texture(scene.client, s.body, face)
        scene.add(s.body, -1, [face], static=True)
    return info


def camera_pose(rng: np.random.Generator, info: WorldInfo, cam: CameraConfig,
                distance_m: Sequence[float] = DISTANCE_M) -> tuple[np.ndarray, np.ndarray]:
    """Random (eye, R_map_cam) looking at the surface of a random object from
    ``distance_m`` (log-uniform) of a point on its tangent plane, up to 45 deg off its
    normal.

    The aim point is offset from an object by up to the half field of view, so objects
    land anywhere in the image, including cut by its border.
    """
    dist = float(np.exp(rng.uniform(*np.log(distance_m))))
    obj = info.objects[int(rng.integers(len(info.objects)))]
    R = obj.R_map_surface
    half_fov = dist * np.array([cam.width / cam.fx, cam.height / cam.fy]) / 2
    aim = obj.centre_map + R[:, :2] @ (rng.uniform(-1, 1, 2) * half_fov)
    tilt = np.radians(MAX_VIEW_ANGLE_DEG) * np.sqrt(rng.random())  # uniform over the cone
    azim = rng.uniform(0, 2 * np.pi)
    eye = aim + dist * (R @ [np.sin(tilt) * np.cos(azim), np.sin(tilt) * np.sin(azim),
                             np.cos(tilt)])
    eye[2] = max(eye[2], 0.15)
    z = (aim - eye) / np.linalg.norm(aim - eye)
    x = np.cross([0.0, 0.0, -1.0], z)
    x /= np.linalg.norm(x)
    R_cam = np.column_stack([x, np.cross(z, x), z])
    roll = Rotation.from_euler('z', rng.uniform(-10, 10), degrees=True).as_matrix()
    return eye, R_cam @ roll


def random_lighting(rng: np.random.Generator, spec: SplitSpec, R_map_wall: np.ndarray
                    ) -> Lighting:
    """Lighting drawn from the split's ranges; direction about the wall normal."""
    az = np.radians(rng.uniform(*spec.light_azimuth_deg)) * rng.choice([-1, 1])
    el = np.radians(rng.uniform(15, 70))
    direction = R_map_wall @ [np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)]
    return Lighting(direction=tuple(direction), color=tuple(rng.uniform(*spec.light_tint, 3)),
                    ambient=float(rng.uniform(*spec.ambient)),
                    diffuse=float(rng.uniform(*spec.diffuse)),
                    specular=float(rng.uniform(0.0, 0.2)))


def add_occluder(scene: Scene, rng: np.random.Generator, eye: np.ndarray,
                 info: WorldInfo) -> int:
    """A bar (pipe, cable, strut) between the camera and a random object; its body id."""
    obj = info.objects[int(rng.integers(len(info.objects)))]
    t = rng.uniform(0.3, 0.85)
    centre = eye + t * (obj.centre_map - eye) + rng.uniform(-0.12, 0.12, 3) * t
    R = Rotation.random(random_state=int(rng.integers(2**31))).as_matrix()
    return _box_body(scene, centre, R, [rng.uniform(0.005, 0.05), rng.uniform(0.1, 0.8),
                                        rng.uniform(0.005, 0.05)], rng)


def add_vehicle(scene: Scene, eye: np.ndarray, R_map_cam: np.ndarray,
                vehicle: VehicleParams = VehicleParams()) -> int:
    """The vehicle posed so that its eye-in-hand camera is at (eye, R_map_cam); its body id."""
    client = scene.client
    base = (Pose(R_map_cam, eye) @ vehicle.camera_in_base().inverse())
    R_map_base, p_base = base.R, base.p
    body = create_vehicle(client, vehicle, p_base.tolist(), 0.0, scene=scene).body
    p.resetBasePositionAndOrientation(body, p_base.tolist(),
                                      Rotation.from_matrix(R_map_base).as_quat().tolist(),
                                      physicsClientId=client)
    return body


def photometric(rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Exposure gain and gamma, optional Gaussian or motion blur, sensor noise."""
    img = np.clip(rgb.astype(np.float32) / 255.0 * np.exp(rng.uniform(-0.5, 0.4)), 0, 1)
    img = img ** rng.uniform(0.75, 1.35)
    r = rng.random()
    if r < 0.2:
        img = cv2.GaussianBlur(img, (0, 0), rng.uniform(0.5, 1.5))
    elif r < 0.35:
        n = int(rng.integers(3, 10))
        kernel: np.ndarray = np.zeros((n, n), np.float32)
        kernel[n // 2] = 1.0 / n
        rot = cv2.getRotationMatrix2D(((n - 1) / 2, (n - 1) / 2), rng.uniform(0, 180), 1.0)
        kernel = cv2.warpAffine(kernel, rot, (n, n))
        img = cv2.filter2D(img, -1, kernel / kernel.sum())
    img = img + rng.normal(0, rng.uniform(0, 0.03), img.shape).astype(np.float32)
    return (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)


def projected_area(centre_map: np.ndarray, R_map_surface: np.ndarray, eye: np.ndarray,
                   R_map_cam: np.ndarray, cam: CameraConfig) -> float:
    """Image area (px^2) of an object's whole front face; inf when it reaches behind the eye."""
    half = textures.OBJECT_SIZE_M / 2
    corners = [centre_map + R_map_surface @ [su * half, sv * half, 0.0]
               for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    pc = np.array([R_map_cam.T @ (c - eye) for c in corners])
    if np.any(pc[:, 2] < cam.near_m):
        return np.inf
    uv = (cam.k_matrix() @ pc.T).T
    return abs(cv2.contourArea((uv[:, :2] / uv[:, 2:]).astype(np.float32)))


def labels_from_segmentation(seg: np.ndarray, info: WorldInfo, eye: np.ndarray,
                             R_map_cam: np.ndarray, cam: CameraConfig
                             ) -> tuple[LabelRows, LabelRows]:
    """YOLO rows [class, cx, cy, w, h] (normalised) of the objects in view, as two lists:
    the sufficiently visible ones (labels) and the rest (regions evaluation ignores)."""
    rows: LabelRows = []
    ignore: LabelRows = []
    for obj in info.objects:
        ys, xs = np.nonzero(seg == obj.body)
        if len(xs) == 0:
            continue
        full = projected_area(obj.centre_map, obj.R_map_surface, eye, R_map_cam, cam)
        x1, x2, y1, y2 = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
        row = [CLASSES.index(obj.cls), (x1 + x2) / 2 / cam.width,
               (y1 + y2) / 2 / cam.height, (x2 - x1) / cam.width, (y2 - y1) / cam.height]
        visible = len(xs) >= MIN_VISIBLE_PX and len(xs) >= MIN_VISIBLE_FRACTION * full
        (rows if visible else ignore).append(row)
    return rows, ignore


@functools.lru_cache(maxsize=None)
def _renderer(renderer: str) -> Renderer:
    """One renderer per process (a GL context is costly to make), reused for every world."""
    return make_renderer(dataclasses.replace(CameraConfig(), renderer=renderer))


def render_world(job: Job) -> list[int]:
    """Render and write the images of one world; returns the class ids it labelled."""
    out, seed, split, world, indices, renderer, distance_m, scenes = job
    spec, cam = SPLITS[split], CameraConfig()
    rng = np.random.default_rng([seed, spec.stream, world])
    client = p.connect(p.DIRECT)
    scene = Scene(client)
    try:
        info = build_random_world(scene, rng, spec, scenes)
        classes: list[int] = []
        for k in indices:
            eye, R_cam = camera_pose(rng, info, cam, distance_m)
            extra = [add_occluder(scene, rng, eye, info)] \
                if rng.random() < OCCLUDER_PROB else []
            if rng.random() < VEHICLE_PROB:
                extra.append(add_vehicle(scene, eye, R_cam))
            light = random_lighting(rng, spec, info.R_map_wall)
            rgb, _, seg = _renderer(renderer).render(scene, eye, R_cam, light, True)
            assert seg is not None      # asked for
            for body in extra:
                p.removeBody(body, physicsClientId=client)
                scene.remove(body)
            rows, ignore = labels_from_segmentation(seg, info, eye, R_cam, cam)
            cv2.imwrite(str(Path(out) / 'images' / f'{k:06d}.png'),
                        cv2.cvtColor(photometric(rgb, rng), cv2.COLOR_RGB2BGR))
            for folder, folder_rows in (('labels', rows), ('ignore', ignore)):
                (Path(out) / folder / f'{k:06d}.txt').write_text(label_text(folder_rows))
            classes.extend(int(r[0]) for r in rows)
        return classes
    finally:
        p.disconnect(client)


def label_text(rows: Iterable[Sequence[float]]) -> str:
    """YOLO label file text for rows [class, cx, cy, w, h]."""
    return ''.join(f'{int(r[0])} ' + ' '.join(f'{v:.6f}' for v in r[1:]) + '\n' for r in rows)


def check_distance(distance_m: Sequence[float]) -> tuple[float, float]:
    """(min, max) camera distance [m]; ConfigError unless 0 < min <= max <= the far clip
    plane (beyond it the wall is not rendered)."""
    lo, hi = (float(d) for d in distance_m)
    far = CameraConfig().far_m
    if not 0.0 < lo <= hi <= far:
        raise ConfigError(f'camera distance range {[lo, hi]} must be 0 < MIN <= MAX <= {far} m '
                          '(the camera\'s far clip plane)')
    return lo, hi


def generate(out: str | os.PathLike[str], n: int, seed: int = 0, split: str = 'train',
             jobs: int = 1, show_progress: bool = True, renderer: str = 'gl',
             distance_m: Sequence[float] = DISTANCE_M, scenes: str = 'wall') -> dict[str, Any]:
    """Write ``n`` labelled images and ``meta.json`` to ``out``; returns the meta dict.

    ``renderer``: the camera's renderer (``gl`` or ``tiny``, see ``uav_tilt_sim.camera``);
    train on images of the renderer the plant uses. ``distance_m``: (min, max) distance of
    the camera from the point it looks at (sets rendered before the mission's ranges grew
    to 5 m used (0.4, 4.0)). ``scenes``: ``wall`` or ``structures`` (the module's text).
    """
    if split not in SPLITS:
        raise ValueError(f'unknown split {split!r}; expected one of {tuple(SPLITS)}')
    if scenes not in SCENES:
        raise ValueError(f'unknown scenes {scenes!r}; expected one of {SCENES}')
    lo, hi = check_distance(distance_m)
    out = Path(out)
    for folder in ('images', 'labels', 'ignore'):
        # a set already there would mix with this one, which meta.json alone describes
        if (out / folder).is_dir() and any((out / folder).iterdir()):
            raise ConfigError(f'{out}: already holds a data set ({folder}/ is not empty)')
    for folder in ('images', 'labels', 'ignore'):
        (out / folder).mkdir(parents=True, exist_ok=True)
    worlds = [(str(out), seed, split, w, range(w * IMAGES_PER_WORLD,
                                               min((w + 1) * IMAGES_PER_WORLD, n)), renderer,
               (lo, hi), scenes)
              for w in range(-(-n // IMAGES_PER_WORLD))]
    bar = tqdm(total=n, desc=f'dataset {split}', unit='img', disable=not show_progress)
    counts = np.zeros(len(CLASSES), int)
    with multiprocessing.get_context('spawn').Pool(jobs) if jobs > 1 else _Serial() as pool:
        for job, classes in zip(worlds, pool.imap(render_world, worlds)):
            counts += np.bincount(classes, minlength=len(CLASSES))
            bar.update(len(job[4]))
    bar.close()
    meta = {'seed': seed, 'split': split, 'n': n, 'classes': list(CLASSES),
            'boxes_per_class': counts.tolist(), 'images_per_world': IMAGES_PER_WORLD,
            'split_spec': dataclasses.asdict(SPLITS[split]),
            'heldout_policy': 'train and heldout use disjoint RNG streams (all textures), '
                              'disjoint wall families and disjoint lighting ranges',
            'camera': dataclasses.asdict(CameraConfig(renderer=renderer)),
            'renderer': _renderer(renderer).name, 'distance_m': [lo, hi], 'scenes': scenes,
            'max_view_angle_deg': MAX_VIEW_ANGLE_DEG, 'occluder_prob': OCCLUDER_PROB,
            'vehicle_prob': VEHICLE_PROB,
            'min_visible_px': MIN_VISIBLE_PX, 'min_visible_fraction': MIN_VISIBLE_FRACTION}
    (out / 'meta.json').write_text(json.dumps(meta, indent=2))
    return meta


class _Serial:
    """In-process stand-in for a worker pool (``imap`` and the context manager)."""

    def __enter__(self) -> '_Serial':
        return self

    def __exit__(self, *exc: object) -> None:
        """Nothing to release; exceptions propagate."""

    @staticmethod
    def imap(fn: Callable[[T], R_], items: Iterable[T]) -> Iterator[R_]:
        return map(fn, items)
