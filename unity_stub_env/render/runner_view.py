"""runner drawn top-down: it has no MuJoCo model (its physics is kinematic, in the track's own
frame), so the track, its props and the car are drawn with Pillow, the view turned so that the
track runs up the picture at the car and centred on the car.

The track frame (``unity_stub_env.tasks.runner``): distance s along the centre line, lateral
offset y (left +), heading theta relative to the track; a Left/Right platform turns the centre
line by +-90 degrees over its 4 m. ``centre_line`` integrates that into the plane."""
from __future__ import annotations

import math

import numpy as np
from PIL import Image, ImageDraw

from unity_stub_env.tasks.runner import CURVATURE, HALF_WIDTH, LANES, PLATFORM_LENGTH

STEP = 0.1  # m between centre-line samples
GROUND = (46, 52, 44)
PLATFORM = ((150, 150, 158), (128, 128, 138))  # alternate shades: the platforms' joins show
TURN = (120, 140, 170)  # a Left/Right platform
COIN = (250, 205, 40)
OBSTACLE = (200, 40, 40)
CAR = (40, 110, 255)
EDGE = (235, 235, 235)


def centre_line(turns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points float [m, 2] and headings float [m] of the centre line every STEP m over the platforms
    with these turns (+1 left, -1 right, 0 straight), starting at the origin heading +y."""
    s = np.arange(0.0, len(turns) * PLATFORM_LENGTH + STEP / 2, STEP)
    platform = np.minimum((s // PLATFORM_LENGTH).astype(int), len(turns) - 1)
    heading = math.pi / 2 + np.concatenate([[0.0], np.cumsum(turns[platform[:-1]] * CURVATURE * STEP)])
    xy = np.zeros((len(s), 2))
    xy[1:] = np.cumsum(STEP * np.column_stack([np.cos(heading[:-1]), np.sin(heading[:-1])]), axis=0)
    return xy, heading


class RunnerView:
    """Frames of the runner agent ``agent``: track, props and car; ``scale`` pixels per metre."""

    def __init__(self, task, agent: int, width: int, height: int, scale: float | None = None) -> None:
        self.task, self.agent, self.width, self.height = task, agent, width, height
        self.scale = scale or height / 11.0
        self.track_key = None
        self.view_heading = math.pi / 2

    def _snapshot(self) -> None:
        """The episode's track and props, kept as they were at its start (the task clears a prop
        once the car has passed it)."""
        task, k = self.task, self.agent
        count = int(task.num_platforms[k])
        self.turns = np.asarray(task.turn[k, :count], float)
        self.props = np.array(task.props[k, :count])
        self.xy, self.heading = centre_line(self.turns)
        self.track_key = (int(task.track_seeds[k]), count, self.turns.tobytes())

    def _pose(self, s: float, y: float) -> tuple[np.ndarray, float]:
        i = min(max(int(round(s / STEP)), 0), len(self.heading) - 1)
        psi = self.heading[i]
        return self.xy[i] + y * np.array([-math.sin(psi), math.cos(psi)]), psi

    def frame(self) -> np.ndarray:
        task, k = self.task, self.agent
        key = (int(task.track_seeds[k]), int(task.num_platforms[k]),
               np.asarray(task.turn[k, :int(task.num_platforms[k])], float).tobytes())
        if key != self.track_key or task.episode_step[k] == 0:
            self._snapshot()
        car, psi = self._pose(float(task.s[k]), float(task.y[k]))
        # turn the view gently towards the track's heading at the car (up = along the track)
        self.view_heading += 0.35 * math.remainder(psi - self.view_heading, 2 * math.pi)
        rot = math.pi / 2 - self.view_heading
        c, s_ = math.cos(rot), math.sin(rot)
        origin = np.array([self.width / 2, self.height * 0.62])

        def screen(points: np.ndarray) -> list[tuple[float, float]]:
            d = np.atleast_2d(points) - car
            x = (c * d[:, 0] - s_ * d[:, 1]) * self.scale
            y = (s_ * d[:, 0] + c * d[:, 1]) * self.scale
            return list(zip((origin[0] + x).tolist(), (origin[1] - y).tolist()))

        image = Image.new("RGB", (self.width, self.height), GROUND)
        draw = ImageDraw.Draw(image)
        normal = np.column_stack([-np.sin(self.heading), np.cos(self.heading)])
        left, right = self.xy + HALF_WIDTH * normal, self.xy - HALF_WIDTH * normal
        per = int(round(PLATFORM_LENGTH / STEP))
        for p in range(len(self.turns)):
            a, b = p * per, min((p + 1) * per, len(self.xy) - 1) + 1
            colour = TURN if self.turns[p] else PLATFORM[p % 2]
            draw.polygon(screen(left[a:b]) + screen(right[a:b][::-1]), fill=colour)
        draw.line(screen(left), fill=EDGE, width=2)
        draw.line(screen(right), fill=EDGE, width=2)
        radius = 0.22 * self.scale
        for p in range(len(self.turns)):
            for lane in range(3):
                code = int(self.props[p, lane])
                if code == 0:
                    continue
                (x, y), = screen(self._pose((p + 0.5) * PLATFORM_LENGTH, float(LANES[lane]))[0])
                box = (x - radius, y - radius, x + radius, y + radius)
                if code > 0:
                    draw.ellipse(box, fill=COIN)
                else:
                    draw.rectangle(box, fill=OBSTACLE)
        theta = psi + float(task.theta[k])
        forward, side = np.array([math.cos(theta), math.sin(theta)]), np.array([-math.sin(theta), math.cos(theta)])
        corners = [car + 0.45 * forward + 0.25 * side, car + 0.45 * forward - 0.25 * side,
                   car - 0.45 * forward - 0.25 * side, car - 0.45 * forward + 0.25 * side]
        draw.polygon(screen(np.array(corners)), fill=CAR, outline=(255, 255, 255))
        return np.asarray(image)

    def close(self) -> None:
        pass
