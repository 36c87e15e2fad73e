"""Inverse kinematics of the arm: damped least squares on MuJoCo's own site Jacobian (``mj_jacSite``)."""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from gym_omnid.constants import (
    IK_DAMPING,
    IK_MAX_ITERS,
    IK_MAX_STEP,
    IK_POS_TOL,
    IK_ROT_TOL,
    IK_ROT_WEIGHT,
)
from gym_omnid.rotations import rotation_error


class DampedLeastSquaresIK:
    """Solves joint positions that put a site at a target pose.

    Works on its own scratch ``MjData`` so the simulation state is never touched. Only the listed
    joints move (hinge or slide joints, one dof each); results are clipped to their ranges.

    Args:
        model: the compiled model.
        site: name of the controlled site (the tool centre point).
        joints: names of the joints the solver may move, in output order.
    """

    def __init__(self, model: mujoco.MjModel, site: str, joints: Sequence[str]) -> None:
        self._model = model
        self._data = mujoco.MjData(model)
        self._site_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)
        if self._site_id < 0:
            raise ValueError(f"site: no site named {site!r} in the model")
        joint_ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name) for name in joints]
        self._qpos_adr = np.array([model.jnt_qposadr[j] for j in joint_ids])
        self._dof_adr = np.array([model.jnt_dofadr[j] for j in joint_ids])
        self._lower = model.jnt_range[joint_ids, 0].copy()
        self._upper = model.jnt_range[joint_ids, 1].copy()
        self._jacp = np.zeros((3, model.nv))
        self._jacr = np.zeros((3, model.nv))
        self._weights = np.array([1.0, 1.0, 1.0, IK_ROT_WEIGHT, IK_ROT_WEIGHT, IK_ROT_WEIGHT])

    def forward(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Site position (3,) and ``world_R_site`` (3, 3) for joint positions ``q``."""
        self._data.qpos[self._qpos_adr] = q
        mujoco.mj_kinematics(self._model, self._data)
        return self._data.site_xpos[self._site_id].copy(), self._data.site_xmat[self._site_id].reshape(
            3, 3
        ).copy()

    def solve(self, xyz_world: np.ndarray, world_R_target: np.ndarray, q_init: np.ndarray) -> np.ndarray:
        """Joint positions (n,) bringing the site to ``xyz_world`` (3,) with orientation ``world_R_target``.

        Starts at ``q_init`` and iterates ``dq = J^T (J J^T + lambda^2 I)^-1 e`` on the weighted 6D
        error until converged or ``IK_MAX_ITERS``; unreachable targets give the best effort found.
        """
        q = np.clip(np.asarray(q_init, dtype=np.float64), self._lower, self._upper)
        for _ in range(IK_MAX_ITERS):
            self._data.qpos[self._qpos_adr] = q
            mujoco.mj_kinematics(self._model, self._data)
            mujoco.mj_comPos(self._model, self._data)
            pos_err = xyz_world - self._data.site_xpos[self._site_id]
            rot_err = rotation_error(world_R_target, self._data.site_xmat[self._site_id].reshape(3, 3))
            if np.linalg.norm(pos_err) < IK_POS_TOL and np.linalg.norm(rot_err) < IK_ROT_TOL:
                break
            mujoco.mj_jacSite(self._model, self._data, self._jacp, self._jacr, self._site_id)
            # 6 x n Jacobian of (position, weighted rotation) w.r.t. the controlled dofs.
            jac = (
                np.concatenate([self._jacp[:, self._dof_adr], self._jacr[:, self._dof_adr]])
                * self._weights[:, None]
            )
            err = np.concatenate([pos_err, rot_err]) * self._weights
            dq = jac.T @ np.linalg.solve(jac @ jac.T + IK_DAMPING**2 * np.eye(6), err)
            step = np.max(np.abs(dq))
            if step > IK_MAX_STEP:
                dq *= IK_MAX_STEP / step
            q = np.clip(q + dq, self._lower, self._upper)
        return q
