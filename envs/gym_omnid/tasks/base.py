"""Task interface and the shared layout sampler (ID square, position-OOD and graded bands; collision-free)."""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from gym_omnid.constants import (
    ID_HALF_EXTENT,
    LAYOUT_MAX_TRIES,
    OOD_HALF_EXTENT,
    POSITION_BANDS,
    REST_SPEED,
)
from gym_omnid.robot import FINGER_GEOMS, HAND_GEOM
from gym_omnid.waypoints import Waypoint


@dataclass(frozen=True)
class Placement:
    """How one object's planar position is sampled.

    Args:
        name: object name (key of the sampled layout).
        nominal_xy: (x, y) centre of its ID square, metres, world frame.
        keepout: radius (m) of the disc it needs free, including room for the open fingers.
        key: key objects follow the ``layout`` variant; the others always stay in their ID square.
    """

    name: str
    nominal_xy: tuple[float, float]
    keepout: float
    key: bool = True


def offset_band(layout: str) -> tuple[float, float]:
    """(inner, outer) half extents (m) of the L-inf band ``inner < |offset|_inf <= outer`` in which the key
    objects of an out-of-distribution ``layout`` are placed: ``"position_ood"`` from the ID square out to
    ``OOD_HALF_EXTENT``, ``"position_band_k"`` at the distance outside the ID square of ``POSITION_BANDS``."""
    if layout == "position_ood":
        return ID_HALF_EXTENT, OOD_HALF_EXTENT
    if layout not in POSITION_BANDS:
        raise ValueError(f"layout: expected position_ood or one of {list(POSITION_BANDS)}, got {layout!r}")
    low, high = POSITION_BANDS[layout]
    return ID_HALF_EXTENT + low, ID_HALF_EXTENT + high


def sample_offset(rng: np.random.Generator, layout: str) -> np.ndarray:
    """(2,) planar offset (m): ``"id"`` uniform in the 10 cm square; any other layout uniform in its band
    ``inner < |offset|_inf <= outer`` around it (:func:`offset_band`), by rejection from the outer square."""
    if layout == "id":
        return rng.uniform(-ID_HALF_EXTENT, ID_HALF_EXTENT, size=2)
    inner, outer = offset_band(layout)
    while True:
        offset = rng.uniform(-outer, outer, size=2)
        if np.max(np.abs(offset)) > inner:
            return offset


def sample_layout(
    rng: np.random.Generator, placements: tuple[Placement, ...], layout: str
) -> dict[str, np.ndarray]:
    """Sample planar positions {name: (2,)} for all placements with pairwise-disjoint keep-out discs.

    Rejection sampling with the episode's generator, so the result is a pure function of its state.
    """
    for _ in range(LAYOUT_MAX_TRIES):
        xy = {
            p.name: np.asarray(p.nominal_xy) + sample_offset(rng, layout if p.key else "id")
            for p in placements
        }
        if all(
            np.linalg.norm(xy[a.name] - xy[b.name]) >= a.keepout + b.keepout
            for i, a in enumerate(placements)
            for b in placements[i + 1 :]
        ):
            return xy
    raise RuntimeError(f"no collision-free layout found in {LAYOUT_MAX_TRIES} tries (layout={layout!r})")


def yaw_quat(yaw: float) -> np.ndarray:
    """(4,) MuJoCo quaternion (w, x, y, z) of a rotation by ``yaw`` rad about world z."""
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def ring_wall_geoms(
    inner_radius: float, thickness: float, z_range: tuple[float, float], segments: int, material: str
) -> str:
    """MJCF geoms: a ring of ``segments`` fixture boxes approximating a cylindrical wall (bowls, pots).

    Args:
        inner_radius: radius of the wall's inner face, m.
        thickness: wall thickness, m.
        z_range: (bottom, top) of the wall in the body frame, m.
        segments: number of boxes around the ring.
        material: MJCF material name.
    """
    half_chord = (inner_radius + thickness) * math.tan(math.pi / segments)
    ring = inner_radius + thickness / 2
    half_height = (z_range[1] - z_range[0]) / 2
    wall_z = z_range[0] + half_height
    walls = []
    for i in range(segments):
        angle = 2 * math.pi * i / segments
        walls.append(
            f'<geom class="fixture" type="box" material="{material}" '
            f'size="{thickness / 2} {half_chord:.4f} {half_height}" '
            f'pos="{ring * math.cos(angle):.4f} {ring * math.sin(angle):.4f} {wall_z}" '
            f'euler="0 0 {angle:.5f}"/>'
        )
    return "\n        ".join(walls)


class Task(abc.ABC):
    """One benchmark task: its objects (MJCF), reset sampler, success test and instruction.

    A task instance belongs to one env and is bound to its compiled model by :meth:`bind`; per-episode
    choices (e.g. the target colour) are stored on the instance by :meth:`reset`.
    """

    name: str

    @abc.abstractmethod
    def mjcf_assets(self) -> str:
        """XML inside ``<asset>``: materials of the task's objects."""

    @abc.abstractmethod
    def mjcf_bodies(self) -> str:
        """XML inside ``<worldbody>``: the task's objects and fixtures."""

    def bind(self, model: mujoco.MjModel) -> None:
        """Look up ids in the compiled model; subclasses extend this."""
        self._model = model
        self._finger_geoms = {mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in FINGER_GEOMS}
        self._finger_geoms.add(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, HAND_GEOM))

    @abc.abstractmethod
    def reset(self, data: mujoco.MjData, rng: np.random.Generator, layout: str) -> None:
        """Sample a layout and episode choices with ``rng`` and write them into ``data`` (qpos, mocap)."""

    @property
    @abc.abstractmethod
    def description(self) -> str:
        """Language instruction of the current episode."""

    def after_step(self, data: mujoco.MjData) -> None:  # noqa: B027 (optional hook, no-op by default)
        """Update per-episode counters once per env step, before :meth:`is_success`; none by default."""

    @abc.abstractmethod
    def is_success(self, data: mujoco.MjData) -> bool:
        """Whether the current state solves the task."""

    @abc.abstractmethod
    def object_positions(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        """World xyz (3,) of the task's key objects, metres."""

    @abc.abstractmethod
    def plan_expert(self, data: mujoco.MjData, start: Waypoint) -> list[Waypoint]:
        """The scripted expert's whole plan for the episode just reset into ``data``, after ``start``.

        Reads privileged state (object poses) once; :func:`gym_omnid.experts.make_expert` replays it.
        """

    def body_yaw(self, data: mujoco.MjData, body: str) -> float:
        """Heading (rad) of the body's x axis about world z (for experts' grasps of flat objects)."""
        world_R_body = data.xmat[self._body_id(body)].reshape(3, 3)
        return math.atan2(float(world_R_body[1, 0]), float(world_R_body[0, 0]))

    # --- helpers shared by tasks ---------------------------------------------------------------
    def _body_id(self, name: str) -> int:
        body_id = mujoco.mj_name2id(self._model, mujoco.mjtObj.mjOBJ_BODY, name)
        if body_id < 0:
            raise KeyError(f"no body named {name!r}")
        return body_id

    def _free_qpos_adr(self, body: str) -> int:
        """qpos address of the free joint of ``body``."""
        return int(self._model.jnt_qposadr[self._model.body_jntadr[self._body_id(body)]])

    def _set_free_pose(self, data: mujoco.MjData, body: str, xyz: np.ndarray, quat: np.ndarray) -> None:
        adr = self._free_qpos_adr(body)
        data.qpos[adr : adr + 3] = xyz
        data.qpos[adr + 3 : adr + 7] = quat

    def _set_mocap_xy(self, data: mujoco.MjData, body: str, xy: np.ndarray) -> None:
        mocap_id = self._model.body_mocapid[self._body_id(body)]
        data.mocap_pos[mocap_id] = (xy[0], xy[1], 0.0)

    def _tilt(self, data: mujoco.MjData, body: str) -> float:
        """Angle (rad) between the body's z axis and world +z."""
        axis_world = data.xmat[self._body_id(body)].reshape(3, 3)[:, 2]
        return math.acos(float(np.clip(axis_world[2], -1.0, 1.0)))

    def _is_resting(self, data: mujoco.MjData, body: str) -> bool:
        """Linear speed of a free body below ``REST_SPEED``."""
        adr = int(self._model.jnt_dofadr[self._model.body_jntadr[self._body_id(body)]])
        return bool(np.linalg.norm(data.qvel[adr : adr + 3]) < REST_SPEED)

    def _touches_gripper(self, data: mujoco.MjData, body: str) -> bool:
        """Whether any geom of ``body`` is in contact with the hand or a finger."""
        geom_pairs = data.contact.geom[: data.ncon]  # ncon, 2
        if len(geom_pairs) == 0:
            return False
        on_body = self._model.geom_bodyid[geom_pairs] == self._body_id(body)  # ncon, 2
        on_gripper = np.isin(geom_pairs, list(self._finger_geoms))  # ncon, 2
        return bool(np.any((on_body[:, 0] & on_gripper[:, 1]) | (on_body[:, 1] & on_gripper[:, 0])))
