"""Procedural, domain-randomised RGB textures for the simulated world (no rclpy).

Orientation convention of every texture: row 0 = top of the panel (up along the
wall), column 0 = left when looking at the wall. Textures are HxWx3 uint8 RGB.
"""
import cv2
import numpy as np
from numpy.typing import NDArray

from uav_tilt_common.targets import OBJECT_CLASSES

OBJECT_SIZE_M = 0.20
# Normalised texture coordinates (u = column / width, v = row / height) of the POI.
POI_UV = {'bolt_plate': (0.5, 0.5)}
# Bolt head across-corners diameter as a fraction of the plate side.
BOLT_HEAD_DIAMETER_FRAC = 0.18


def _fractal_noise(rng, shape_hw, octaves=4, base_cells=4):
    """Smooth value noise in [-1, 1], summed over octaves of halving amplitude."""
    h, w = shape_hw
    out = np.zeros((h, w), np.float32)
    amp, total = 1.0, 0.0
    for k in range(octaves):
        cells = base_cells * 2 ** k
        grid = rng.uniform(-1.0, 1.0, (cells + 1, cells + 1)).astype(np.float32)
        out += amp * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
        total += amp
        amp *= 0.5
    return np.clip(out / total, -1.0, 1.0)


def _random_colour(rng, lo=0, hi=255):
    return rng.uniform(lo, hi, 3).astype(np.float32)


def _finish(img_f, rng, noise_sigma=4.0, brightness=(0.85, 1.15)):
    """Global brightness and pixel noise, then clip to uint8."""
    img_f = img_f * rng.uniform(*brightness)
    img_f = img_f + rng.normal(0.0, noise_sigma, img_f.shape).astype(np.float32)
    return np.clip(img_f, 0, 255).astype(np.uint8)


def _grid(shape_hw):
    yy, xx = np.mgrid[0:shape_hw[0], 0:shape_hw[1]].astype(np.float32)
    return xx, yy


def _paint(img, signed_dist_px, colour):
    """Anti-aliased fill where the signed distance (negative inside) is below zero.

    Coverage = clip(0.5 - d) is unbiased at edges, so shapes keep their exact centres.
    """
    cover = np.clip(0.5 - signed_dist_px, 0.0, 1.0)[..., None]
    img *= 1.0 - cover
    img += cover * np.asarray(colour, np.float32)


def _circle(img, centre_px, radius_px, colour):
    xx, yy = _grid(img.shape)
    _paint(img, np.hypot(xx - centre_px[0], yy - centre_px[1]) - radius_px, colour)


def _polygon(img, points_px, colour):
    """Fill a convex polygon given by its vertices in pixel-index coordinates."""
    xx, yy = _grid(img.shape)
    pts = np.asarray(points_px, np.float32)
    centre = pts.mean(axis=0)
    dist = np.full(img.shape[:2], -np.inf, np.float32)
    for p0, p1 in zip(pts, np.roll(pts, -1, axis=0)):
        normal = np.array([p1[1] - p0[1], p0[0] - p1[0]], np.float32)
        normal /= np.linalg.norm(normal)
        if np.dot(normal, centre - p0) > 0:
            normal = -normal
        dist = np.maximum(dist, normal[0] * (xx - p0[0]) + normal[1] * (yy - p0[1]))
    _paint(img, dist, colour)


def _segment(img, p0_px, p1_px, half_width_px, colour):
    xx, yy = _grid(img.shape)
    p0, d = np.asarray(p0_px, np.float32), np.subtract(p1_px, p0_px).astype(np.float32)
    t = np.clip(((xx - p0[0]) * d[0] + (yy - p0[1]) * d[1]) / float(d @ d), 0.0, 1.0)
    _paint(img, np.hypot(xx - p0[0] - t * d[0], yy - p0[1] - t * d[1]) - half_width_px,
           colour)


def _uv_to_px(uv, size_px):
    """Normalised texture coordinates -> pixel-index coordinates (pixel centres at integers)."""
    return (uv[0] * size_px - 0.5, uv[1] * size_px - 0.5)


def _regular_polygon(centre_px, radius_px, n, angle_rad):
    a = angle_rad + 2.0 * np.pi * np.arange(n) / n
    return np.stack([centre_px[0] + radius_px * np.cos(a),
                     centre_px[1] + radius_px * np.sin(a)], axis=1)


def _bolt_plate(rng, s):
    base = np.array([190, 190, 192], np.float32) + rng.uniform(-15, 15, 3).astype(np.float32)
    # Brushed metal: noise stretched along the rows.
    streaks = cv2.resize(rng.normal(0, 1, (s, max(s // 32, 2))).astype(np.float32), (s, s),
                         interpolation=cv2.INTER_LINEAR)
    img = base + 10.0 * streaks[..., None] + 8.0 * _fractal_noise(rng, (s, s))[..., None]
    edge = max(int(0.03 * s), 1)
    bevel = np.ones((s, s), np.float32)
    bevel[:edge, :] = bevel[-edge:, :] = bevel[:, :edge] = bevel[:, -edge:] = 0.85
    img = img * bevel[..., None]
    rivet_colour = base * 0.75
    for fx, fy in ((0.1, 0.1), (0.9, 0.1), (0.1, 0.9), (0.9, 0.9)):
        _circle(img, (fx * s, fy * s), 0.025 * s, rivet_colour)
        _circle(img, (fx * s - 0.006 * s, fy * s - 0.006 * s), 0.008 * s, base * 1.1)
    centre = _uv_to_px(POI_UV['bolt_plate'], s)
    dark = float(rng.uniform(25, 50))
    # Washer slightly darker than the plate, then the (point-symmetric) hexagon head.
    _circle(img, centre, 0.6 * BOLT_HEAD_DIAMETER_FRAC * s, base * 0.8)
    hexagon = _regular_polygon(centre, 0.5 * BOLT_HEAD_DIAMETER_FRAC * s, 6,
                               rng.uniform(0, np.pi / 3))
    _polygon(img, hexagon, (dark, dark, dark))
    return _finish(img, rng, noise_sigma=3.0)


def _gauge(rng, s):
    housing = rng.uniform(40, 120) + rng.uniform(-8, 8, 3).astype(np.float32)
    img = np.ones((s, s, 3), np.float32) * housing
    img += 10.0 * _fractal_noise(rng, (s, s))[..., None]
    centre = _uv_to_px((0.5, 0.5), s)
    _circle(img, centre, 0.47 * s, (35, 35, 40))
    face = np.array([245, 245, 240], np.float32) - rng.uniform(0, 20, 3).astype(np.float32)
    _circle(img, centre, 0.40 * s, face)
    for k in range(11):
        a = np.deg2rad(135.0 + 27.0 * k)
        r0 = 0.30 if k % 5 else 0.26
        p0 = (centre[0] + r0 * s * np.cos(a), centre[1] + r0 * s * np.sin(a))
        p1 = (centre[0] + 0.36 * s * np.cos(a), centre[1] + 0.36 * s * np.sin(a))
        _segment(img, p0, p1, 0.006 * s, (20, 20, 20))
    # A red arc marks the danger zone of the dial.
    cv2.ellipse(img, (int(centre[0]), int(centre[1])), (int(0.33 * s), int(0.33 * s)), 0,
                360 + 45 - 54, 360 + 45, (200, 30, 30), max(s // 60, 1), cv2.LINE_AA)
    a = np.deg2rad(rng.uniform(135.0, 405.0))
    tip = (centre[0] + 0.32 * s * np.cos(a), centre[1] + 0.32 * s * np.sin(a))
    tail = (centre[0] - 0.06 * s * np.cos(a), centre[1] - 0.06 * s * np.sin(a))
    _segment(img, tail, tip, 0.009 * s, (25, 25, 25))
    _circle(img, centre, 0.02 * s, (25, 25, 25))
    return _finish(img, rng)


def _hazard_sign(rng, s):
    backing = np.array([235, 235, 235], np.float32) - rng.uniform(0, 30, 3).astype(np.float32)
    img = np.ones((s, s, 3), np.float32) * backing
    img += 6.0 * _fractal_noise(rng, (s, s))[..., None]
    yellow = np.array([250, 205, 20], np.float32) + rng.uniform(-15, 5, 3).astype(np.float32)
    black = (20.0, 20.0, 20.0)
    tilt = rng.uniform(-0.05, 0.05)
    outer = _regular_polygon((s / 2.0, 0.56 * s), 0.50 * s, 3, -np.pi / 2 + tilt)
    inner = _regular_polygon((s / 2.0, 0.56 * s), 0.38 * s, 3, -np.pi / 2 + tilt)
    _polygon(img, outer, black)
    _polygon(img, inner, yellow)
    bar = np.array([[-0.03, 0.36], [0.03, 0.36], [0.02, 0.62], [-0.02, 0.62]]) * s
    bar[:, 0] += s / 2.0
    _polygon(img, bar, black)
    _circle(img, (s / 2.0, 0.70 * s), 0.03 * s, black)
    return _finish(img, rng)


_OBJECTS = {'bolt_plate': _bolt_plate, 'gauge': _gauge, 'hazard_sign': _hazard_sign}


def object_texture(cls: str, rng: np.random.Generator, size_px: int = 256
                   ) -> NDArray[np.uint8]:
    """Randomised texture (size_px x size_px x 3 RGB uint8) of inspection object ``cls``."""
    if cls not in _OBJECTS:
        raise ValueError(f'unknown object class {cls!r}; expected one of {OBJECT_CLASSES}')
    return _OBJECTS[cls](rng, int(size_px))


def _concrete(rng, s):
    grey = rng.uniform(100, 200)
    base = grey + rng.uniform(-15, 15, 3)
    img = base + 35.0 * _fractal_noise(rng, (s, s), octaves=6)[..., None]
    pores = rng.random((s, s)) < 0.004
    img[pores] *= 0.6
    return img


def _bricks(rng, s):
    mortar = _random_colour(rng, 150, 220)
    brick = np.array([rng.uniform(120, 190), rng.uniform(40, 90), rng.uniform(30, 70)], np.float32)
    img = np.ones((s, s, 3), np.float32) * mortar
    rows = int(rng.integers(6, 12))
    bh = s / rows
    bw = 2.0 * bh
    gap = max(bh * 0.08, 1.0)
    for r in range(rows):
        offset = (r % 2) * bw / 2.0
        x = -offset
        while x < s:
            tone = brick * rng.uniform(0.8, 1.15)
            cv2.rectangle(img, (int(x + gap), int(r * bh + gap)), (int(x + bw - gap),
                          int((r + 1) * bh - gap)), tuple(float(c) for c in tone), -1)
            x += bw
    return img + 10.0 * _fractal_noise(rng, (s, s), octaves=5)[..., None]


def _painted_panels(rng, s):
    paint = _random_colour(rng, 60, 230)
    img = np.ones((s, s, 3), np.float32) * paint
    img += 6.0 * _fractal_noise(rng, (s, s))[..., None]
    n = int(rng.integers(2, 5))
    seam = paint * 0.6
    for k in range(1, n):
        x = int(k * s / n)
        cv2.line(img, (x, 0), (x, s - 1), tuple(float(c) for c in seam), max(s // 200, 1))
    return img


def _stripes(rng, s):
    c0, c1 = _random_colour(rng), _random_colour(rng)
    period = rng.uniform(0.05, 0.25) * s
    angle = rng.uniform(0, np.pi)
    yy, xx = np.mgrid[0:s, 0:s].astype(np.float32)
    phase = (xx * np.cos(angle) + yy * np.sin(angle)) / period
    mask = ((phase % 1.0) < 0.5)[..., None]
    img = np.where(mask, c0, c1).astype(np.float32)
    return img + 8.0 * _fractal_noise(rng, (s, s))[..., None]


WALL_FAMILIES = ('concrete', 'bricks', 'painted_panels', 'stripes')
_WALLS = {'concrete': _concrete, 'bricks': _bricks, 'painted_panels': _painted_panels,
          'stripes': _stripes}


def wall_texture(rng: np.random.Generator, size_px: int = 512, family: str | None = None
                 ) -> NDArray[np.uint8]:
    """Randomised wall texture; ``family`` (one of WALL_FAMILIES) is drawn when None."""
    family = family or WALL_FAMILIES[int(rng.integers(len(WALL_FAMILIES)))]
    return _finish(_WALLS[family](rng, int(size_px)), rng, noise_sigma=3.0)


def _asphalt(rng, s):
    grey = rng.uniform(40, 95)
    img = grey + rng.uniform(-6, 6, 3) + 18.0 * _fractal_noise(rng, (s, s), octaves=6)[..., None]
    stones = rng.random((s, s)) < 0.02
    img[stones] *= rng.uniform(1.2, 1.6)
    return img


def _gravel(rng, s):
    base = rng.uniform(90, 160) + rng.uniform(-10, 10, 3)
    img = np.ones((s, s, 3), np.float32) * base
    for _ in range(int(s * s / 60)):
        c = (int(rng.integers(s)), int(rng.integers(s)))
        tone = tuple(float(v) for v in base * rng.uniform(0.6, 1.3))
        cv2.circle(img, c, int(rng.integers(1, 4)), tone, -1)
    return img + 8.0 * _fractal_noise(rng, (s, s))[..., None]


def _grass(rng, s):
    green = np.array([rng.uniform(40, 90), rng.uniform(80, 140), rng.uniform(20, 60)], np.float32)
    img = green * (1.0 + 0.35 * _fractal_noise(rng, (s, s), octaves=6)[..., None])
    blades = cv2.resize(rng.normal(0, 1, (s // 4, s)).astype(np.float32), (s, s))
    return img + 12.0 * blades[..., None]


GROUND_FAMILIES = ('concrete', 'asphalt', 'gravel', 'grass')
_GROUNDS = {'concrete': _concrete, 'asphalt': _asphalt, 'gravel': _gravel, 'grass': _grass}


def ground_texture(rng: np.random.Generator, size_px: int = 256, family: str | None = None
                   ) -> NDArray[np.uint8]:
    """Randomised ground texture (one GROUND_FAMILIES member, drawn when None)."""
    family = family or GROUND_FAMILIES[int(rng.integers(len(GROUND_FAMILIES)))]
    return _finish(_GROUNDS[family](rng, int(size_px)), rng, noise_sigma=3.0)
