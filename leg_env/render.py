"""Drawing the planar leg from ``(q, anchor, lam, params)``: frames as arrays, or a window.

pygame draws on an off-screen ``Surface``, which needs no display and no GL, so
``rgb_array`` frames work headless. pygame is imported only inside the functions
here, the first time a frame is asked for; importing this module is free.

The picture (world units scaled so a leg length ``l1 + l2`` is half the frame height, or less
in a narrow frame; camera centred on the contact point): the ground with the contact point, the
friction cone (faint), the shank, the thigh, the torso (a schematic box centred at the hip and
turned by ``th_b``), the joints, the whole-body centre of mass, and the ground's force on the foot
as an arrow (the robot's weight is drawn as ``0.5 (l1 + l2)``), green while the force is
feasible and red when a contact constraint is violated (``lam_y < 0`` or outside the cone).

On the unilateral ground (``mode`` given) the foot shows its contact mode: a green disc in stick, an
orange disc with an arrow along the sliding direction in slip, a hollow blue ring in flight (with a
dashed line down to the ground); the friction cone is drawn only in contact. A step with an impact
draws a yellow burst at the foot whose size grows with the impulse. A horizontal push on the torso
(``push``, the push-recovery task) is a purple arrow ending at the hip, drawn at the scale of the ground's
force (the robot's weight as half a leg length).
"""

from __future__ import annotations

import math
import os

import numpy as np

from .physics.params import LegParams

__all__ = ["draw", "Viewer"]

SKY = (236, 241, 246)
GROUND = (120, 112, 100)
GROUND_LINE = (60, 55, 50)
CONE = (200, 205, 190)
TORSO = (55, 65, 90)
THIGH = (60, 110, 175)
SHANK = (95, 150, 215)
JOINT = (245, 245, 245)
OUTLINE = (25, 25, 30)
COM = (230, 150, 20)
FEASIBLE = (30, 160, 60)
VIOLATED = (215, 35, 35)
SLIPPING = (235, 130, 20)
FLYING = (40, 120, 220)
BURST = (250, 200, 30)
PUSH = (150, 60, 190)


def _pygame():
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    try:
        import pygame
    except ImportError as e:  # pragma: no cover - depends on the install
        raise ImportError('rendering needs pygame: pip install "leg-env[render]"') from e
    return pygame


class _Camera:
    """World (metres, y up) to pixels (y down), centred on the contact point."""

    def __init__(self, anchor, params: LegParams, width: int, height: int):
        leg = params.l1 + params.l2
        self.scale = min(0.5 * height, 0.45 * width) / leg
        self.ox = width / 2.0 - self.scale * float(anchor[0])
        self.oy = 0.85 * height + self.scale * float(anchor[1])  # ground at 15% from the bottom

    def __call__(self, x: float, y: float) -> tuple[float, float]:
        return self.ox + self.scale * x, self.oy - self.scale * y


def _bar(pygame, surface, camera, a, b, width_m: float, colour) -> None:
    """A link from world point ``a`` to ``b`` as a filled, outlined rectangle ``width_m`` thick."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    n = math.hypot(dx, dy) or 1.0
    nx, ny = -dy / n * width_m / 2.0, dx / n * width_m / 2.0
    corners = [camera(a[0] + nx, a[1] + ny), camera(b[0] + nx, b[1] + ny), camera(b[0] - nx, b[1] - ny), camera(a[0] - nx, a[1] - ny)]
    pygame.draw.polygon(surface, colour, corners)
    pygame.draw.polygon(surface, OUTLINE, corners, 2)


def _disc(pygame, surface, centre, radius_px: float, colour) -> None:
    c = (round(centre[0]), round(centre[1]))
    r = max(2, round(radius_px))
    pygame.draw.circle(surface, colour, c, r)
    pygame.draw.circle(surface, OUTLINE, c, r, 2)


def _arrow(pygame, surface, start, end, colour, width_px: int) -> None:
    sx, sy = start
    ex, ey = end
    length = math.hypot(ex - sx, ey - sy)
    if length < 1.0:
        return
    ux, uy = (ex - sx) / length, (ey - sy) / length
    head = min(0.35 * length, 4.0 * width_px + 8.0)
    bx, by = ex - head * ux, ey - head * uy
    pygame.draw.line(surface, colour, (sx, sy), (bx, by), width_px)
    half = 0.5 * head
    pygame.draw.polygon(surface, colour, [(ex, ey), (bx - half * uy, by + half * ux), (bx + half * uy, by - half * ux)])


def _paint(pygame, surface, q, anchor, lam, params: LegParams, violated: bool, mu: float | None, mode=None, impulse=None, push=0.0) -> None:
    """Paint one frame of the robot on ``surface`` (see the module docstring)."""
    width, height = surface.get_size()
    p = params
    camera = _Camera(anchor, p, width, height)
    leg = p.l1 + p.l2
    x_b, y_b, th_b, q1, q2 = (float(v) for v in q)
    th1 = th_b + q1
    th2 = th1 + q2
    hip = (x_b, y_b)
    knee = (x_b + p.l1 * math.cos(th1), y_b + p.l1 * math.sin(th1))
    foot = (knee[0] + p.l2 * math.cos(th2), knee[1] + p.l2 * math.sin(th2))

    surface.fill(SKY)
    ground_y = camera(0.0, float(anchor[1]))[1]
    pygame.draw.rect(surface, GROUND, (0, round(ground_y), width, height))
    pygame.draw.line(surface, GROUND_LINE, (0, round(ground_y)), (width, round(ground_y)), 3)

    contact = camera(float(anchor[0]), float(anchor[1]))
    flying = mode is not None and int(mode) == 3
    if mu is not None and mu > 0.0 and not flying:  # friction cone: the feasible force directions
        r = 0.45 * leg
        for side in (-1.0, 1.0):
            s = side * mu / math.hypot(1.0, mu)
            c = 1.0 / math.hypot(1.0, mu)
            pygame.draw.line(surface, CONE, contact, camera(anchor[0] + r * s, anchor[1] + r * c), 2)

    # torso: a schematic box centred at the hip (its COM), turned by th_b
    half_l, half_w = 0.3 * leg, 0.08 * leg
    ct, st = math.cos(th_b), math.sin(th_b)
    box = [camera(x_b + ct * u - st * v, y_b + st * u + ct * v) for u, v in ((-half_l, -half_w), (half_l, -half_w), (half_l, half_w), (-half_l, half_w))]
    pygame.draw.polygon(surface, TORSO, box)
    pygame.draw.polygon(surface, OUTLINE, box, 2)

    link_w = 0.06 * leg
    _bar(pygame, surface, camera, hip, knee, link_w, THIGH)
    _bar(pygame, surface, camera, knee, foot, link_w, SHANK)
    joint_px = 0.045 * leg * camera.scale
    _disc(pygame, surface, camera(*hip), joint_px, JOINT)
    _disc(pygame, surface, camera(*knee), joint_px, JOINT)
    _disc(pygame, surface, camera(*foot), 0.7 * joint_px, OUTLINE)
    if mode is not None:
        _contact_mode_marker(pygame, surface, camera, foot, float(anchor[1]), int(mode), joint_px)
    if impulse is not None and math.hypot(float(impulse[0]), float(impulse[1])) > 0.0:
        _burst(pygame, surface, camera(*foot), math.hypot(float(impulse[0]), float(impulse[1])) / max(p.total_mass, 1e-9), joint_px)

    # whole-body centre of mass
    m = p.total_mass
    c1 = (x_b + p.c1 * math.cos(th1), y_b + p.c1 * math.sin(th1))
    c2 = (knee[0] + p.c2 * math.cos(th2), knee[1] + p.c2 * math.sin(th2))
    com = ((p.m_b * x_b + p.m1 * c1[0] + p.m2 * c2[0]) / m, (p.m_b * y_b + p.m1 * c1[1] + p.m2 * c2[1]) / m)
    cx, cy = camera(*com)
    r = max(3, round(0.6 * joint_px))
    pygame.draw.circle(surface, COM, (round(cx), round(cy)), r)
    pygame.draw.line(surface, OUTLINE, (cx - r, cy), (cx + r, cy), 1)
    pygame.draw.line(surface, OUTLINE, (cx, cy - r), (cx, cy + r), 1)

    # the ground's force on the foot, weight drawn as half a leg length
    weight = p.weight if p.weight > 0.0 else 1.0
    lam_x, lam_y = float(lam[0]), float(lam[1])
    if math.isfinite(lam_x) and math.isfinite(lam_y):
        k = 0.5 * leg / weight
        tip = camera(foot[0] + k * lam_x, foot[1] + k * lam_y)
        _arrow(pygame, surface, camera(*foot), tip, VIOLATED if violated else FEASIBLE, max(3, round(0.012 * height)))
    push = float(push)
    if push != 0.0 and math.isfinite(push):  # the push on the torso's COM (the hip), pointing at it
        tail = camera(x_b - 0.5 * leg / weight * push, y_b)
        _arrow(pygame, surface, tail, camera(x_b, y_b), PUSH, max(3, round(0.012 * height)))


def _contact_mode_marker(pygame, surface, camera, foot, ground: float, mode: int, joint_px: float) -> None:
    """The foot's contact mode: 0 stick, 1 / 2 slip forward / backward, 3 flight (``leg_env.physics.contact``)."""
    centre = camera(*foot)
    r = max(4, round(1.1 * joint_px))
    c = (round(centre[0]), round(centre[1]))
    if mode == 3:
        pygame.draw.circle(surface, FLYING, c, r, 3)
        gx, gy = camera(foot[0], ground)
        y = centre[1] + r
        while y < gy:  # a dashed drop line to the ground
            pygame.draw.line(surface, FLYING, (gx, y), (gx, min(gy, y + 6)), 2)
            y += 12
        return
    pygame.draw.circle(surface, FEASIBLE if mode == 0 else SLIPPING, c, r)
    pygame.draw.circle(surface, OUTLINE, c, r, 2)
    if mode in (1, 2):
        side = 1.0 if mode == 1 else -1.0
        _arrow(pygame, surface, (c[0] + side * r, c[1] + r), (c[0] + side * 4 * r, c[1] + r), SLIPPING, 3)


def _burst(pygame, surface, centre, speed_change: float, joint_px: float) -> None:
    """An impact: yellow rays around the foot, longer for a larger impulse (``speed_change = |P| / m`` [m/s])."""
    length = joint_px * (1.5 + 4.0 * min(1.0, speed_change))
    for k in range(8):
        a = k * math.pi / 4.0
        start = (centre[0] + 0.8 * joint_px * math.cos(a), centre[1] + 0.8 * joint_px * math.sin(a))
        end = (centre[0] + length * math.cos(a), centre[1] + length * math.sin(a))
        pygame.draw.line(surface, BURST, start, end, 3)


def draw(
    q, anchor, lam, params: LegParams, violated: bool = False, width: int = 480, height: int = 480, mu: float | None = None,
    mode: int | None = None, impulse=None, push: float = 0.0,
) -> np.ndarray:  # fmt: skip
    """One frame of the robot, off-screen (no display needed).

    Args:
        q: ``(5,)`` configuration ``[x_b, y_b, th_b, q1, q2]``.
        anchor: ``(2,)`` foot contact point (the camera centres on it).
        lam: ``(2,)`` contact force on the foot [N], drawn as an arrow from the foot.
        params: physical parameters (lengths, masses for the centre of mass).
        violated: draw the force red (a contact constraint is violated) instead of green.
        width, height: frame size in pixels.
        mu: friction coefficient; if given, the friction cone is drawn at the contact point.
        mode: the contact mode on the unilateral ground (``leg_env.physics.contact`` constants), or None (pinned).
        impulse: ``(2,)`` impact impulse of the last step [N s] (a burst is drawn if it is not zero).
        push: horizontal force on the torso's COM over the last step [N] (an arrow is drawn if it is not zero).

    Returns:
        ``(height, width, 3)`` uint8 RGB frame.
    """
    pygame = _pygame()
    surface = pygame.Surface((int(width), int(height)))
    _paint(pygame, surface, q, anchor, lam, params, violated, mu, mode, impulse, push)
    return np.ascontiguousarray(np.transpose(pygame.surfarray.array3d(surface), (1, 0, 2)))


OFFSCREEN_DRIVERS = ("offscreen", "dummy")
"""SDL video drivers that show nothing: SDL falls back to them when there is no display."""


class Viewer:
    """A window that shows frames at ``fps`` (the env's ``human`` render mode).

    Raises:
        RuntimeError: SDL cannot open a window (a failing video driver); the message names the driver.

    Warns (``UserWarning``) when SDL runs an off-screen driver (``offscreen``, ``dummy``) that the user
    did not ask for through ``SDL_VIDEODRIVER``, as it does without a display: no window shows, and the
    frames are still paced to ``fps``.
    """

    def __init__(self, width: int, height: int, fps: float, title: str = "leg_env/PlanarLegStance-v0"):
        self._pygame = pygame = _pygame()
        try:
            pygame.display.init()
            pygame.display.set_caption(title)
            self.screen = pygame.display.set_mode((int(width), int(height)))
        except pygame.error as e:
            driver = os.environ.get("SDL_VIDEODRIVER", "SDL's default")
            pygame.display.quit()
            raise RuntimeError(
                f'render_mode="human" could not open a window ({e}; video driver: {driver}); '
                'use render_mode="rgb_array" without a display'
            ) from e
        driver = pygame.display.get_driver()
        if driver in OFFSCREEN_DRIVERS and os.environ.get("SDL_VIDEODRIVER") != driver:
            import warnings

            warnings.warn(
                f'render_mode="human": SDL has no display and fell back to its {driver!r} video driver, so no window '
                'will show (set DISPLAY or WAYLAND_DISPLAY, or use render_mode="rgb_array" for frames)',
                stacklevel=2,
            )
        self.clock = pygame.time.Clock()
        self.fps = fps

    def show(self, q, anchor, lam, params: LegParams, violated: bool = False, mu: float | None = None, mode=None, impulse=None, push=0.0) -> None:
        """Draw the robot in the window (arguments of ``draw``) and wait for the next frame time."""
        pygame = self._pygame
        _paint(pygame, self.screen, q, anchor, lam, params, violated, mu, mode, impulse, push)
        pygame.event.pump()
        pygame.display.flip()
        self.clock.tick(self.fps)

    def close(self) -> None:
        pygame = self._pygame
        pygame.display.quit()
