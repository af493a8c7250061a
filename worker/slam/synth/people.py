"""People-like movers: articulated figures of ellipsoids walking elliptical loops on the floor (room frame).

Legs and arms swing with a gait phase tied to the distance walked; clothes are striped so features land on
the movers too (the culling stage must find and drop them).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Material:
    """Two RGB colours (float32 (3,), 0..255) alternating in `stripes` bands along the part's long axis."""

    a: np.ndarray
    b: np.ndarray
    stripes: float


@dataclass(frozen=True)
class Ellipsoid:
    """`center` (3,) m, `axes` (3, 3) columns = local axes in the room frame, `radii` (3,) m."""

    center: np.ndarray
    axes: np.ndarray
    radii: np.ndarray
    material: Material


@dataclass(frozen=True)
class Walker:
    """A figure walking an ellipse: centre `loop_c` (2,), semi-axes `loop_r` (2,) m, `omega` rad/s (sign =
    direction), start angle `phase`; `scale` ~ height / 1.75 m."""

    loop_c: np.ndarray
    loop_r: np.ndarray
    omega: float
    phase: float
    scale: float
    skin: Material
    shirt: Material
    trousers: Material
    hair: Material

    def position(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Floor position (2,) and unit heading (2,) at time `t` seconds."""
        a = self.omega * t + self.phase
        p = self.loop_c + self.loop_r * np.array([np.cos(a), np.sin(a)])
        v = self.omega * self.loop_r * np.array([-np.sin(a), np.cos(a)])
        return p, v / max(np.linalg.norm(v), 1e-9)

    def parts(self, t: float) -> list[Ellipsoid]:
        """The figure's ellipsoids at time `t`."""
        p, fwd = self.position(t)
        s = self.scale
        walked = abs(self.omega) * t * float(self.loop_r.mean())
        g = 2 * np.pi * walked / (1.3 * s)  # one stride ~ 1.3 m
        right = np.array([fwd[1], -fwd[0]])
        # Body frame: columns x = right, y = forward, z = up.
        B = np.array([[right[0], fwd[0], 0.0], [right[1], fwd[1], 0.0], [0.0, 0.0, 1.0]])
        bob = 0.025 * s * abs(np.cos(g))
        origin = np.array([p[0], p[1], bob])

        def world(local) -> np.ndarray:
            return origin + B @ (np.asarray(local) * s)

        def blob(local_c, radii, mat: Material, R=np.eye(3)) -> Ellipsoid:
            return Ellipsoid(world(local_c), B @ R, np.asarray(radii) * s, mat)

        def limb(joint, angle, length, radius, mat: Material, tilt: float = 0.0) -> tuple[Ellipsoid, np.ndarray]:
            # Swing about the body x axis: angle > 0 moves the limb forward.
            d = np.array([np.sin(tilt), np.sin(angle), -np.cos(angle)])
            d /= np.linalg.norm(d)
            z = d
            x = np.cross([0.0, 1.0, 0.0], z)
            x /= np.linalg.norm(x)
            R = np.stack([x, np.cross(z, x), z], axis=1)
            end = np.asarray(joint) + d * length
            return blob(np.asarray(joint) + d * length / 2, (radius, radius, length / 2 + radius * 0.4), mat, R), end

        parts = [
            blob((0, 0, 1.18), (0.19, 0.12, 0.28), self.shirt),
            blob((0, 0, 0.93), (0.17, 0.11, 0.13), self.trousers),
            blob((0, 0.01, 1.62), (0.095, 0.105, 0.12), self.skin),
            blob((0, -0.015, 1.67), (0.1, 0.1, 0.08), self.hair),
        ]
        for side in (-1, 1):
            swing = side * 0.42 * np.sin(g)
            knee = 0.55 * max(0.0, np.sin(g * side + 0.9 * side))
            upper, k = limb((side * 0.09, 0, 0.9), swing, 0.45, 0.075, self.trousers)
            lower, _ = limb(k, swing - knee, 0.44, 0.06, self.trousers)
            arm_swing = -0.8 * swing
            uarm, e = limb((side * 0.235, 0, 1.4), arm_swing, 0.29, 0.05, self.shirt, tilt=side * 0.12)
            farm, _ = limb(e, arm_swing + 0.35, 0.27, 0.042, self.skin, tilt=side * 0.05)
            parts += [upper, lower, uarm, farm]
        return parts


def _mat(rng: np.random.Generator, lo: int, hi: int, stripes: float) -> Material:
    a = rng.uniform(lo, hi, 3).astype(np.float32)
    b = np.clip(a * rng.uniform(0.3, 0.6) + rng.uniform(0, 60, 3), 0, 255).astype(np.float32)
    return Material(a, b, stripes)


def make_walkers(k: int, walk_lo: np.ndarray, walk_hi: np.ndarray, rng: np.random.Generator) -> list[Walker]:
    """`k` walkers looping inside the floor rectangle `walk_lo`..`walk_hi` (2,) at about 0.8-1.2 m/s."""
    walkers = []
    half = np.maximum((walk_hi - walk_lo) / 2, 0.3)
    mid = (walk_hi + walk_lo) / 2
    for _ in range(k):
        r = np.array([rng.uniform(0.45, 1.0) * half[0], rng.uniform(0.3, 0.9) * half[1]])
        c = mid + rng.uniform(-1, 1, 2) * np.maximum(half - r, 0)
        speed = rng.uniform(0.8, 1.2)
        omega = speed / float(r.mean()) * (1 if rng.random() < 0.5 else -1)
        skin_tone = rng.uniform(0.45, 1.0)
        skin = Material(np.array([230, 185, 150], np.float32) * skin_tone,
                        np.array([215, 170, 140], np.float32) * skin_tone, 0.0)
        hair_colour = np.full(3, rng.uniform(15, 90), np.float32)
        hair = Material(hair_colour, hair_colour, 0.0)
        walkers.append(Walker(c, r, float(omega), float(rng.uniform(0, 2 * np.pi)), float(rng.uniform(0.92, 1.08)),
                              skin, _mat(rng, 40, 240, float(rng.integers(3, 8))), _mat(rng, 20, 110, 2.0), hair))
    return walkers
