"""``omnid-calibrate hand-eye`` end to end on rendered images.

The gym_omnid arm's wrist camera ``cam_wrist`` sees the checkerboard that ``test_calibrate_cameras`` renders
(``calibration_testing.CHECKERBOARD``) lying on the table, at ``VIEWS`` arm poses aimed at it from 33-50 cm,
tilted up to 35 degrees and rolled up to 40 degrees; the images are rendered from the env's own scene (its
MJCF with the board added and the task's loose objects moved under the table). The gripper frame is the tool
centre point (``env.tcp_pose()``, fixed to the hand like the camera); the truth is
``env.camera_calibration("cam_wrist")`` at each pose. Tolerances: camera position on the gripper within 3 mm,
rotation within 0.5 degree, focal lengths within 1 %, the board's pose in the base frame within 3 mm and 0.5
degree. Measured when written (``pytest -s`` prints them): park 0.82 mm / 0.043 deg, tsai with the first run's
intrinsics 0.81 mm / 0.043 deg; focal 0.16 %; board pose 0.10 mm / 0.017 deg; the board's implied pose spread
over the views by at most 0.17 mm / 0.05 deg, reprojected at 0.06 px RMS.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import mujoco
import numpy as np
import pytest
import yaml
from calibration_testing import CHECKERBOARD, PX_PER_SQUARE, WORLD_T_BOARD, board_args, pose_errors, tcp_T
from gym_omnid.constants import ARM_JOINTS, DEFAULT_RIG, HOME_JOINTS, WRIST_CAMERA
from gym_omnid.env import OmniDEnv
from gym_omnid.ik import DampedLeastSquaresIK
from gym_omnid.rigs import RIG_PLACEMENTS
from gym_omnid.robot import TCP_SITE
from gym_omnid.scene import build_mjcf
from gym_omnid.tasks import make_task

from lerobot_omnid.calibration.board import board_image
from lerobot_omnid.calibration.calibrate import main
from lerobot_omnid.calibration.hand_eye import HandEyeCalibration, invert_rigid, load_hand_eye_file
from lerobot_omnid.calibration.rig_file import load_calibration_meta
from lerobot_omnid.calibration.solve import load_board_pose

HEIGHT, WIDTH = 480, 640
VIEWS = 10
POSITION_TOL_M = 0.003
ROTATION_TOL_DEG = 0.5
FOCAL_REL_TOL = 0.01
BOARD_ABOVE_CENTRE = 0.12  # the board's centre this far (x its distance) above the optical axis
IK_MISS_M = 0.005  # m: an arm pose missing its target by more than this is drawn again
VIEW_MARGIN_PX = 10  # px: the board (with a square of margin) this far inside the image
FINGERTIPS_V_PX = 400  # px: the fingertips cover the wrist image below this row


class WristBoardScene:
    """The env's scene with the board lying on the table at ``WORLD_T_BOARD``, rendered by ``cam_wrist``.

    The board is a textured plane (texture columns along the plane's +x, rows along its -y, facing +z), so
    the board frame is the plane frame turned by 180 degrees about x and shifted to the origin corner (as in
    ``test_calibrate_cameras.BoardScene``).
    """

    def __init__(self, texture_path: Path) -> None:
        image = board_image(CHECKERBOARD, PX_PER_SQUARE)
        cv2.imwrite(str(texture_path), image)
        metres_per_px = CHECKERBOARD.square_size / PX_PER_SQUARE
        half_x, half_y = image.shape[1] * metres_per_px / 2, image.shape[0] * metres_per_px / 2
        origin = (PX_PER_SQUARE // 2 + PX_PER_SQUARE) * metres_per_px  # margin + one square
        plane_T_board = np.diag([1.0, -1.0, -1.0, 1.0])
        plane_T_board[:2, 3] = (-half_x + origin, half_y - origin)
        world_T_plane = WORLD_T_BOARD @ invert_rigid(plane_T_board)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, world_T_plane[:3, :3].ravel())
        xml = build_mjcf(make_task("select_apple"), (HEIGHT, WIDTH), RIG_PLACEMENTS[DEFAULT_RIG])
        asset = f'<texture name="board" type="2d" file="{texture_path}"/>'
        asset += '<material name="board" texture="board" specular="0" shininess="0"/>'
        body = (
            f'<body name="board" pos="{" ".join(map(str, world_T_plane[:3, 3]))}" '
            f'quat="{" ".join(map(str, quat))}"><geom type="plane" size="{half_x} {half_y} 0.01" '
            f'material="board" contype="0" conaffinity="0"/></body>'
        )
        xml = xml.replace("<asset>", f"<asset>{asset}", 1).replace("</worldbody>", f"{body}</worldbody>", 1)
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        for joint in range(self.model.njnt):  # the task's loose objects: under the table
            if self.model.jnt_type[joint] == mujoco.mjtJoint.mjJNT_FREE:
                adr = self.model.jnt_qposadr[joint]
                self.data.qpos[adr : adr + 3] = (0.0, 0.0, -0.5)
        self.arm_qpos = [self.model.joint(name).qposadr[0] for name in ARM_JOINTS]
        self.camera = self.model.camera(WRIST_CAMERA).id
        self.renderer = mujoco.Renderer(self.model, HEIGHT, WIDTH)

    def render(self, q_arm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """BGR image of ``cam_wrist`` with the arm at ``q_arm``, and the camera's pose (x, 3x3) used."""
        self.data.qpos[self.arm_qpos] = q_arm
        mujoco.mj_forward(self.model, self.data)
        self.renderer.update_scene(self.data, camera=WRIST_CAMERA)
        pose = (self.data.cam_xpos[self.camera].copy(), self.data.cam_xmat[self.camera].reshape(3, 3).copy())
        return self.renderer.render()[:, :, ::-1].copy(), pose

    def close(self) -> None:
        self.renderer.close()


def set_arm(env: OmniDEnv, q_arm: np.ndarray) -> None:
    for name, q in zip(ARM_JOINTS, q_arm, strict=True):
        env.data.qpos[env.model.joint(name).qposadr[0]] = q
    mujoco.mj_forward(env.model, env.data)


def aimed_arm_poses(
    env: OmniDEnv, tcp_T_cam: np.ndarray, K: np.ndarray, rng: np.random.Generator
) -> list[np.ndarray]:
    """``VIEWS`` joint positions putting the wrist camera 33-50 cm from the board's centre, looking at it
    from up to 35 degrees off the vertical, rolled up to 40 degrees (IK of the env's arm). Drawn again:
    views whose board would not lie inside the image above the fingertips, targets IK misses."""
    ik = DampedLeastSquaresIK(env.model, TCP_SITE, ARM_JOINTS)
    nx, ny = CHECKERBOARD.inner_corners
    size = CHECKERBOARD.square_size
    centre = (WORLD_T_BOARD @ [(nx - 1) / 2 * size, (ny - 1) / 2 * size, 0.0, 1.0])[:3]
    outline_board = np.array([[x, y, 0.0, 1.0] for x in (-size, nx * size) for y in (-size, ny * size)])
    q, poses = np.array(HOME_JOINTS), []
    for _ in range(10 * VIEWS):
        tilt, azimuth = math.radians(rng.uniform(10, 35)), rng.uniform(0, 2 * math.pi)
        direction = [math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth), math.cos(tilt)]
        distance = rng.uniform(0.33, 0.5)
        z_axis = -np.asarray(direction)
        x_axis = np.cross(z_axis, [1.0, 0.0, 0.0])
        x_axis /= np.linalg.norm(x_axis)
        roll = math.radians(rng.uniform(-40, 40))
        x_axis = math.cos(roll) * x_axis + math.sin(roll) * np.cross(z_axis, x_axis)
        y_axis = np.cross(z_axis, x_axis)
        world_T_cam = np.eye(4)
        world_T_cam[:3, :3] = np.stack([x_axis, y_axis, z_axis], axis=1)
        # Shifted along the image's down axis: the board sits above the image centre, clear of the fingers.
        world_T_cam[:3, 3] = centre - distance * z_axis + BOARD_ABOVE_CENTRE * distance * y_axis
        uvw = K @ (invert_rigid(world_T_cam) @ WORLD_T_BOARD @ outline_board.T)[:3]
        u, v = uvw[:2] / uvw[2]
        if u.min() < VIEW_MARGIN_PX or u.max() > WIDTH - VIEW_MARGIN_PX or v.min() < VIEW_MARGIN_PX:
            continue
        if v.max() > FINGERTIPS_V_PX:
            continue
        world_T_tcp = world_T_cam @ invert_rigid(tcp_T_cam)
        solved = ik.solve(world_T_tcp[:3, 3], world_T_tcp[:3, :3], q)
        if np.linalg.norm(ik.forward(solved)[0] - world_T_tcp[:3, 3]) < IK_MISS_M:
            q = solved
            poses.append(q)
        if len(poses) == VIEWS:
            return poses
    raise AssertionError(f"the arm reached {len(poses)} of the {VIEWS} views")


@pytest.fixture(scope="module")
def wrist_views(tmp_path_factory) -> dict:
    """Rendered views, the gripper poses file, and the truth (``tcp_T_cam``, K)."""
    folder = tmp_path_factory.mktemp("hand_eye")
    env = OmniDEnv("select_apple", cameras=(WRIST_CAMERA,), image_size=(HEIGHT, WIDTH), render_mode=None)
    scene = WristBoardScene(folder / "texture.png")
    try:
        truth = env.camera_calibration(WRIST_CAMERA)
        tcp_T_cam = invert_rigid(tcp_T(env)) @ invert_rigid(truth["T_cam_world"])
        poses = {}
        for i, q in enumerate(aimed_arm_poses(env, tcp_T_cam, truth["K"], np.random.default_rng(0))):
            set_arm(env, q)
            image, (cam_xpos, cam_xmat) = scene.render(q)
            calib = env.camera_calibration(WRIST_CAMERA)
            np.testing.assert_allclose(
                cam_xpos, env.data.cam_xpos[env.model.camera(WRIST_CAMERA).id], atol=1e-9
            )
            np.testing.assert_allclose(cam_xmat.ravel(), env.data.cam_xmat[env.model.camera(WRIST_CAMERA).id])
            # The camera is rigid on the hand: the same tcp_T_cam at every pose.
            np.testing.assert_allclose(tcp_T(env) @ tcp_T_cam, invert_rigid(calib["T_cam_world"]), atol=1e-9)
            name = f"view{i:02d}.png"
            cv2.imwrite(str(folder / name), image)
            poses[name] = tcp_T(env).tolist()
    finally:
        scene.close()
        env.close()
    (folder / "poses.yaml").write_text(yaml.safe_dump({"T_base_gripper": poses}))
    return {"folder": folder, "poses": poses, "tcp_T_cam": tcp_T_cam, "K": truth["K"]}


def hand_eye_args(views: dict, output: Path, *extra: str, camera: str = "wrist") -> list[str]:
    folder = views["folder"]
    return [
        "hand-eye",
        "--camera",
        camera,
        *board_args(CHECKERBOARD),
        "--images",
        str(folder / "view*.png"),
        "--gripper-poses",
        str(folder / "poses.yaml"),
        "--output",
        str(output),
        *extra,
    ]


def check_against_truth(calib: HandEyeCalibration, meta: dict, wrist_views: dict) -> str:
    """Assert ``T_gripper_cam`` within tolerance of the env's and a good fit; the line to print."""
    # pose_errors compares transforms into the camera frame: pass the inverses (cam_T_gripper).
    position_err, rotation_err = pose_errors(
        invert_rigid(np.asarray(calib.T_gripper_cam)), invert_rigid(wrist_views["tcp_T_cam"])
    )
    line = (
        f"{meta['method']}: camera on the gripper {position_err * 1000:.2f} mm {rotation_err:.3f} deg; board "
        f"spread max {meta['board_spread_mm_max']:.2f} mm {meta['board_spread_deg_max']:.3f} deg, "
        f"reprojection {meta['reprojection_rms_px']:.2f} px"
    )
    assert position_err < POSITION_TOL_M and rotation_err < ROTATION_TOL_DEG, line
    assert meta["views"] == VIEWS and meta["reprojection_rms_px"] < 1.0, line
    return line


def test_hand_eye_recovers_the_wrist_camera(wrist_views, tmp_path, capsys):
    """Intrinsics and ``T_gripper_cam`` from the rendered views, then again with those intrinsics reused and
    another method, replacing the camera in the same file; both match the env, and so does the board pose
    written for the fixed cameras."""
    key = "observation.images.wrist"
    output, board_pose = tmp_path / "hand_eye.yaml", tmp_path / "board_pose.yaml"
    assert main(hand_eye_args(wrist_views, output, "--board-pose-output", str(board_pose))) == 0
    printed = capsys.readouterr().out
    assert "warning" not in printed, printed
    first, first_meta = load_hand_eye_file(output)[key], load_calibration_meta(output)[key]
    report = [check_against_truth(first, first_meta, wrist_views)]
    K, K_true = np.asarray(first.K), wrist_views["K"]
    focal_err = float(np.abs(np.diag(K)[:2] / np.diag(K_true)[:2] - 1).max())
    position_err, rotation_err = pose_errors(load_board_pose(board_pose), WORLD_T_BOARD)
    report.append(f"focal {focal_err:.3%}; board pose {position_err * 1000:.2f} mm {rotation_err:.3f} deg")
    assert focal_err < FOCAL_REL_TOL and first_meta["intrinsics_views"] == VIEWS, report[-1]
    assert position_err < POSITION_TOL_M and rotation_err < ROTATION_TOL_DEG, report[-1]

    again_args = hand_eye_args(wrist_views, output, "--method", "tsai", "--intrinsics-from", str(output))
    assert main(again_args) == 0, capsys.readouterr().err
    again, again_meta = load_hand_eye_file(output), load_calibration_meta(output)
    assert list(again) == [key] and again[key].K == first.K and again_meta[key]["intrinsics"] == "reused"
    report.append(check_against_truth(again[key], again_meta[key], wrist_views))
    print("\n".join(report))


def test_hand_eye_bad_input_is_named(wrist_views, tmp_path, capsys):
    """A missing pose is an error naming the image; poses swapped between two images, or given inverted
    (``T_gripper_base``), are caught by the residuals and named in a warning or an error."""
    poses = wrist_views["poses"]
    output, poses_file = tmp_path / "hand_eye.yaml", tmp_path / "poses.yaml"
    args = hand_eye_args(wrist_views, output, "--pinhole")
    args[args.index("--gripper-poses") + 1] = str(poses_file)
    short = {k: v for k, v in poses.items() if k != "view03.png"}
    poses_file.write_text(yaml.safe_dump({"T_base_gripper": short}))
    assert main(args) == 2
    assert "no T_base_gripper for 1 image(s): ['view03.png']" in capsys.readouterr().err
    assert not output.exists()
    swapped = {**poses, "view02.png": poses["view05.png"], "view05.png": poses["view02.png"]}
    poses_file.write_text(yaml.safe_dump({"T_base_gripper": swapped}))
    assert main(args) == 0
    assert "check that each pose belongs to its image" in capsys.readouterr().out
    inverted = {k: invert_rigid(np.asarray(v)).tolist() for k, v in poses.items()}
    poses_file.write_text(yaml.safe_dump({"T_base_gripper": inverted}))
    main(args)  # an error or a warning, depending on what OpenCV makes of inconsistent views
    printed = capsys.readouterr()
    assert "does the file hold T_gripper_base instead of T_base_gripper?" in printed.out + printed.err
