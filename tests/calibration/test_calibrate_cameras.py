"""``omnid-calibrate`` on images rendered by MuJoCo: a board texture at known poses, seen by cameras placed
exactly like the benchmark env's five cameras; the recovered calibration must match the env's.

Tolerances (640x480 renders, 10 intrinsics views per camera, one view of the board lying on the table):
focal lengths within 1 %, principal point within 2 px, camera centre within 1 cm, rotation within 0.5 deg.
Measured when written (worst camera; ``pytest -s`` prints them): checkerboard 9x6 (30 mm): focal 0.06 %,
principal point 0.4 px, centre 1.0 mm, rotation 0.09 deg; ChArUco 7x5 (60 mm): focal 0.16 %, principal
point 1.3 px, centre 3.5 mm, rotation 0.18 deg.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import cv2
import mujoco
import numpy as np
import pytest
from calibration_testing import (
    CAMS,
    CHARUCO,
    CHECKERBOARD,
    PX_PER_SQUARE,
    REPO_ID,
    SIZE,
    board_args,
    make_uncalibrated_dataset,
    pose_errors,
)
from gym_omnid.calibration import invert_rigid, mujoco_camera_calibration
from gym_omnid.constants import CAMERA_FOVY, CAMERAS
from gym_omnid.env import OmniDEnv
from gym_omnid.scene import CAMERA_POSES, look_at_xyaxes

from lerobot_omnid.calibration.attach_calibration import main as attach_main
from lerobot_omnid.calibration.board import BoardSpec, board_image, detect_board
from lerobot_omnid.calibration.calibrate import main
from lerobot_omnid.calibration.rig_file import load_calibration_file, load_calibration_meta
from lerobot_omnid.calibration.schema import CalibrationError
from lerobot_omnid.calibration.solve import load_board_pose, world_T_board_from_points, world_T_board_on_table

HEIGHT, WIDTH = 480, 640
INTRINSICS_VIEWS = 10
BOARD_ON_TABLE = (0.42, 0.12, 20.0)  # x, y (m), yaw (deg) of the board lying on the table for extrinsics
FOCAL_REL_TOL = 0.01
PRINCIPAL_TOL_PX = 2.0
POSITION_TOL_M = 0.01
ROTATION_TOL_DEG = 0.5


class BoardScene:
    """A MuJoCo scene with the env's five cameras and a mocap plane textured with the board image.

    The plane's texture spans the whole plane: texture columns run along the plane's +x, rows along its
    -y, and the plane faces +z. The board frame (origin at the first inner corner, x right, y down on the
    image, z into the board) is therefore the plane frame turned by 180 degrees about x, shifted to the
    origin corner.
    """

    def __init__(self, board: BoardSpec, texture_path: Path) -> None:
        image = board_image(board, PX_PER_SQUARE)
        cv2.imwrite(str(texture_path), image)
        metres_per_px = board.square_size / PX_PER_SQUARE
        half_x, half_y = image.shape[1] * metres_per_px / 2, image.shape[0] * metres_per_px / 2
        origin_px = PX_PER_SQUARE // 2 + PX_PER_SQUARE  # default margin + one square, pixel edges
        self.plane_T_board = np.diag([1.0, -1.0, -1.0, 1.0])
        self.plane_T_board[:2, 3] = (-half_x + origin_px * metres_per_px, half_y - origin_px * metres_per_px)
        cameras = "\n".join(
            f'<camera name="{name}" pos="{" ".join(map(str, pos))}" fovy="{CAMERA_FOVY}" '
            f'xyaxes="{" ".join(f"{v:.9f}" for v in look_at_xyaxes(pos, target))}"/>'
            for name, (pos, target) in CAMERA_POSES.items()
        )
        xml = f"""
<mujoco>
  <statistic extent="2" center="0.5 0 0.3"/>
  <visual>
    <global offwidth="{WIDTH}" offheight="{HEIGHT}"/>
    <quality shadowsize="0" offsamples="0"/>
    <headlight ambient="0.6 0.6 0.6" diffuse="0.3 0.3 0.3" specular="0 0 0"/>
  </visual>
  <asset>
    <texture name="board" type="2d" file="{texture_path}"/>
    <texture name="sky" type="skybox" builtin="gradient" rgb1="0.6 0.6 0.6" rgb2="0.3 0.3 0.3" width="32"
             height="32"/>
    <material name="board" texture="board" specular="0" shininess="0"/>
  </asset>
  <worldbody>
    <body name="board" mocap="true"><geom type="plane" size="{half_x} {half_y} 0.01" material="board"/></body>
    {cameras}
  </worldbody>
</mujoco>"""
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        self.renderer = mujoco.Renderer(self.model, HEIGHT, WIDTH)

    def truth(self, cam: str) -> dict:
        i = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, cam)
        d = self.data
        return mujoco_camera_calibration(
            self.model.cam_fovy[i], d.cam_xpos[i], d.cam_xmat[i], (HEIGHT, WIDTH)
        )

    def render(self, cam: str, world_T_board: np.ndarray) -> np.ndarray:
        """BGR image of the board at ``world_T_board`` seen by ``cam``."""
        world_T_plane = world_T_board @ np.linalg.inv(self.plane_T_board)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, world_T_plane[:3, :3].ravel())
        self.data.mocap_pos[0], self.data.mocap_quat[0] = world_T_plane[:3, 3], quat
        mujoco.mj_forward(self.model, self.data)
        self.renderer.update_scene(self.data, camera=cam)
        return self.renderer.render()[:, :, ::-1].copy()

    def close(self) -> None:
        self.renderer.close()


def intrinsics_poses(board: BoardSpec, cam_T_world: np.ndarray, rng: np.random.Generator) -> list[np.ndarray]:
    """``world_T_board`` of views that fill much of the image, tilted up to 35 degrees, spread over it."""
    nx, ny = board.inner_corners
    centre_board = np.array([(nx - 1) / 2, (ny - 1) / 2, 0.0]) * board.square_size
    scale = (nx + 1) * board.square_size / 0.30  # keep the board's size in the image similar
    world_T_cam = invert_rigid(cam_T_world)
    poses = []
    for _ in range(INTRINSICS_VIEWS):
        depth = rng.uniform(0.45, 0.65) * scale
        offset = np.array([rng.uniform(-0.24, 0.24), rng.uniform(-0.16, 0.16)]) * depth
        tilt = np.radians([rng.uniform(-35, 35), rng.uniform(-35, 35), 0.0])
        R = cv2.Rodrigues(tilt)[0] @ cv2.Rodrigues(np.radians([0.0, 0.0, rng.uniform(-20, 20)]))[0]
        cam_T_board = np.eye(4)
        cam_T_board[:3, :3] = R
        cam_T_board[:3, 3] = np.array([*offset, depth]) - R @ centre_board
        poses.append(world_T_cam @ cam_T_board)
    return poses


@pytest.fixture(scope="module")
def env_truth() -> dict[str, dict]:
    env = OmniDEnv("select_apple", image_size=(HEIGHT, WIDTH), render_mode=None)
    try:
        return {cam: env.camera_calibration(cam) for cam in CAMERAS}
    finally:
        env.close()


def render_board_views(
    board: BoardSpec, folder: Path, env_truth: dict[str, dict]
) -> dict[str, tuple[str, str]]:
    """Per camera: a glob of the intrinsics images and the image of the board lying on the table."""
    scene = BoardScene(board, folder / "texture.png")
    try:
        images = {}
        for k, cam in enumerate(CAMERAS):
            truth = scene.truth(cam)
            np.testing.assert_allclose(truth["K"], env_truth[cam]["K"], atol=1e-9)
            np.testing.assert_allclose(truth["T_cam_world"], env_truth[cam]["T_cam_world"], atol=1e-6)
            rng = np.random.default_rng(k)
            for i, world_T_board in enumerate(intrinsics_poses(board, truth["T_cam_world"], rng)):
                cv2.imwrite(str(folder / f"{cam}_view{i:02d}.png"), scene.render(cam, world_T_board))
            on_table = scene.render(cam, world_T_board_on_table(*BOARD_ON_TABLE))
            cv2.imwrite(str(folder / f"{cam}_on_table.png"), on_table)
            images[cam] = (str(folder / f"{cam}_view*.png"), str(folder / f"{cam}_on_table.png"))
    finally:
        scene.close()
    return images


@pytest.fixture(scope="module")
def renders(tmp_path_factory, env_truth):
    """``renders(board)``: the rendered images of ``board`` (made once per module)."""
    cache: dict[str, dict[str, tuple[str, str]]] = {}

    def get(board: BoardSpec) -> dict[str, tuple[str, str]]:
        if board.kind not in cache:
            cache[board.kind] = render_board_views(board, tmp_path_factory.mktemp(board.kind), env_truth)
        return cache[board.kind]

    return get


def calibrate_args(board: BoardSpec, cam: str, images: tuple[str, str], output: Path) -> list[str]:
    x, y, yaw = BOARD_ON_TABLE
    return [
        "camera",
        "--camera",
        cam,
        *board_args(board),
        "--intrinsics-images",
        images[0],
        "--extrinsics-image",
        images[1],
        "--board-on-table",
        str(x),
        str(y),
        str(yaw),
        "--output",
        str(output),
    ]


@pytest.mark.parametrize("board", [CHECKERBOARD, CHARUCO], ids=["checkerboard", "charuco"])
def test_calibration_matches_the_env_cameras(board, renders, env_truth, tmp_path, capsys):
    """All five cameras through the CLI into one YAML file, compared with the env's calibration."""
    images = renders(board)
    output = tmp_path / "rig.yaml"
    for cam in CAMERAS:
        assert main(calibrate_args(board, cam, images[cam], output)) == 0, capsys.readouterr().err
    calibrations, meta = load_calibration_file(output), load_calibration_meta(output)
    assert sorted(calibrations) == [f"observation.images.{c}" for c in CAMERAS]
    report = []
    for cam in CAMERAS:
        key = f"observation.images.{cam}"
        calib, truth = calibrations[key], env_truth[cam]
        K, K_true = np.asarray(calib.K), truth["K"]
        focal_err = np.abs(np.diag(K)[:2] / np.diag(K_true)[:2] - 1).max()
        principal_err = np.abs(K[:2, 2] - K_true[:2, 2]).max()
        position_err, rotation_err = pose_errors(np.asarray(calib.T_cam_world), truth["T_cam_world"])
        report.append(
            f"{board.kind} {cam}: focal {focal_err:.3%} principal {principal_err:.2f} px "
            f"centre {position_err * 1000:.1f} mm rotation {rotation_err:.3f} deg"
        )
        assert calib.image_size == (HEIGHT, WIDTH)
        assert focal_err < FOCAL_REL_TOL, report[-1]
        assert principal_err < PRINCIPAL_TOL_PX, report[-1]
        assert position_err < POSITION_TOL_M, report[-1]
        assert rotation_err < ROTATION_TOL_DEG, report[-1]
        assert meta[key]["intrinsics_views"] == INTRINSICS_VIEWS
        assert meta[key]["intrinsics_rms_px"] < 0.5 and meta[key]["extrinsics_rms_px"] < 1.0
    print("\n".join(report))


def test_pinhole_calibration_attached_to_a_lower_resolution_dataset(renders, env_truth, tmp_path):
    """Record with LeRobot (here: a dataset without calibration at 48x36), calibrate at 640x480 with a
    pinhole model, attach (K rescaled): the dataset then carries the env's calibration at its size."""
    board = CHECKERBOARD
    images = renders(board)
    output = tmp_path / "rig.json"
    for cam in CAMS:
        assert main([*calibrate_args(board, cam, images[cam], output), "--pinhole"]) == 0
    assert all(not any(c.distortion) for c in load_calibration_file(output).values())
    root = tmp_path / "dataset"
    make_uncalibrated_dataset(root)
    assert attach_main(["--root", str(root), "--calibration", str(output)]) == 0

    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    from lerobot_omnid.calibration.schema import calibration_from_feature_info

    features = LeRobotDatasetMetadata(REPO_ID, root=root).features
    env = OmniDEnv("select_apple", image_size=SIZE, render_mode=None)
    try:
        for cam in CAMS:
            key = f"observation.images.{cam}"
            calib, truth = calibration_from_feature_info(key, features[key]), env.camera_calibration(cam)
            K = np.asarray(calib.K)
            assert calib.image_size == SIZE
            np.testing.assert_allclose(np.diag(K)[:2], np.diag(truth["K"])[:2], rtol=FOCAL_REL_TOL)
            np.testing.assert_allclose(K[:2, 2], truth["K"][:2, 2], atol=PRINCIPAL_TOL_PX * SIZE[0] / HEIGHT)
            position_err, rotation_err = pose_errors(np.asarray(calib.T_cam_world), truth["T_cam_world"])
            assert position_err < POSITION_TOL_M and rotation_err < ROTATION_TOL_DEG
    finally:
        env.close()


@pytest.mark.parametrize("board", [CHECKERBOARD, CHARUCO], ids=["checkerboard", "charuco"])
def test_board_frame_on_the_printed_image(board, tmp_path):
    """``omnid-calibrate board`` writes an image whose top-left inner corner is the origin, x right, y down;
    a checkerboard turned upside down is still read in the board's own frame."""
    path = tmp_path / "board.png"
    assert main(["board", *board_args(board), "--px-per-square", "40", "--output", str(path)]) == 0
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    image = cv2.copyMakeBorder(image, 20, 20, 20, 20, cv2.BORDER_CONSTANT, value=255)
    origin = 20 + 20 + 40 - 0.5  # border + margin (half a square) + one square, pixel centres at integers
    detection = detect_board(image, board)
    first = np.argmin(np.linalg.norm(detection.xyz_board, axis=1))
    np.testing.assert_allclose(detection.xyz_board[first], 0.0)
    np.testing.assert_allclose(detection.uv_pix[first], [origin, origin], atol=1.0)
    along_x = np.argmin(np.linalg.norm(detection.xyz_board - [board.square_size, 0, 0], axis=1))
    np.testing.assert_allclose(detection.uv_pix[along_x] - detection.uv_pix[first], [40, 0], atol=1.0)
    along_y = np.argmin(np.linalg.norm(detection.xyz_board - [0, board.square_size, 0], axis=1))
    np.testing.assert_allclose(detection.uv_pix[along_y] - detection.uv_pix[first], [0, 40], atol=1.0)
    turned = detect_board(cv2.rotate(image, cv2.ROTATE_180), board)
    first = np.argmin(np.linalg.norm(turned.xyz_board, axis=1))
    h, w = image.shape
    np.testing.assert_allclose(turned.uv_pix[first], [w - 1 - origin, h - 1 - origin], atol=1.0)


def test_board_pose_inputs(tmp_path):
    """Measured corners and a pose file give the same pose as ``--board-on-table``; bad input is named."""
    world_T_board = world_T_board_on_table(0.4, 0.1, 30.0, 0.005)
    nx, ny = CHECKERBOARD.inner_corners
    corners = [(nx - 1, 0), (0, ny - 1)]
    points = [world_T_board[:3, 3]] + [
        world_T_board[:3, :3] @ np.array([i, j, 0.0]) * CHECKERBOARD.square_size + world_T_board[:3, 3]
        for i, j in corners
    ]
    np.testing.assert_allclose(world_T_board_from_points(*points, CHECKERBOARD), world_T_board, atol=1e-12)
    with pytest.raises(CalibrationError, match=r"last inner corner along x is 0\.3"):
        world_T_board_from_points(points[0], points[0] + [0.3, 0, 0], points[2], CHECKERBOARD)
    # Face up with yaw 0: x forward, y to the robot's right, z down into the table.
    np.testing.assert_allclose(
        world_T_board_on_table(0, 0, 0)[:3, :3], np.diag([1.0, -1.0, -1.0]), atol=1e-12
    )
    path = tmp_path / "pose.yaml"
    path.write_text("T_world_board:\n" + "".join(f"  - {row}\n" for row in world_T_board.tolist()))
    np.testing.assert_allclose(load_board_pose(path), world_T_board, atol=1e-12)
    path.write_text("T_world_board: [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]")
    with pytest.raises(
        CalibrationError, match=r"pose\.yaml\.T_world_board: rotation part is not orthonormal"
    ):
        load_board_pose(path)


def test_bad_input_is_named(tmp_path, capsys):
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((120, 160, 3), 128, np.uint8))
    base = [
        "camera",
        "--camera",
        "front",
        "--extrinsics-image",
        str(blank),
        "--output",
        str(tmp_path / "r.yaml"),
    ]
    on_table = ["--board-on-table", "0.4", "0", "0"]
    symmetric = ["--board", "checkerboard", "--pattern", "8x6", "--square-size", "0.03"]
    assert main([*base, *symmetric, "--intrinsics-images", str(blank), *on_table]) == 2
    assert "looks the same turned by 180 degrees" in capsys.readouterr().err
    args = [*base, *board_args(CHECKERBOARD), *on_table]
    assert main([*args, "--intrinsics-images", str(blank), str(blank)]) == 2
    assert "the board was found in 0 image(s), need at least 4" in capsys.readouterr().err
    assert main([*args, "--intrinsics-images", str(tmp_path / "none_*.png")]) == 2
    assert "matches no file" in capsys.readouterr().err
    assert main([*args]) == 2
    assert "exactly one of --intrinsics-images and --intrinsics-from" in capsys.readouterr().err
    assert not (tmp_path / "r.yaml").exists()


def test_extrinsics_only_after_a_camera_moved(renders, env_truth, tmp_path, capsys):
    """``--intrinsics-from`` reuses K and distortion; only the board image at the known pose is needed.
    A board pose file with the board's z axis up (the wrong way) puts the camera under the table: warned."""
    board = CHARUCO
    images = renders(board)
    first = tmp_path / "first.yaml"
    assert main(calibrate_args(board, "cam_b", images["cam_b"], first)) == 0
    moved = tmp_path / "moved.yaml"
    shutil.copy(images["cam_b"][1], tmp_path / "again.png")
    args = calibrate_args(board, "cam_b", ("unused", str(tmp_path / "again.png")), moved)
    args[args.index("--intrinsics-images") : args.index("--intrinsics-images") + 2] = [
        "--intrinsics-from",
        str(first),
    ]
    assert main(args) == 0
    calib, reused = load_calibration_file(moved), load_calibration_file(first)
    key = "observation.images.cam_b"
    assert calib[key].K == reused[key].K and calib[key].distortion == reused[key].distortion
    assert load_calibration_meta(moved)[key]["intrinsics"] == "reused"
    position_err, rotation_err = pose_errors(
        np.asarray(calib[key].T_cam_world), env_truth["cam_b"]["T_cam_world"]
    )
    assert position_err < POSITION_TOL_M and rotation_err < ROTATION_TOL_DEG
    assert "below the table top" not in capsys.readouterr().out
    wrong = world_T_board_on_table(*BOARD_ON_TABLE) @ np.diag([1.0, -1.0, -1.0, 1.0])  # z up
    pose_file = tmp_path / "pose.json"
    pose_file.write_text(json.dumps({"T_world_board": wrong.tolist()}))
    args[args.index("--board-on-table") : args.index("--board-on-table") + 4] = [
        "--board-pose",
        str(pose_file),
    ]
    assert main(args) == 0
    assert "below the table top; check the board pose" in capsys.readouterr().out


def test_readme_walkthrough_commands_parse():
    """The commands of the "bring your own robot" walkthrough (docs/calibration.md) parse."""
    import shlex

    from lerobot_omnid.calibration import attach_calibration
    from lerobot_omnid.calibration import calibrate as calibrate_cameras

    doc = (Path(__file__).parents[2] / "docs" / "calibration.md").read_text()
    section = doc.split("## Bring your own robot")[1].split("\n## ")[0]
    parsers = {
        "omnid-calibrate": calibrate_cameras.build_parser,
        "omnid-attach-calibration": attach_calibration.build_parser,
    }
    blocks = re.findall(r"```(bash|python)\n(.*?)```", section, flags=re.S)
    checked = 0
    for language, block in blocks:
        if language == "python":
            compile(block, "docs/calibration.md", "exec")
            continue
        for command in block.replace("\\\n", " ").splitlines():
            words = shlex.split(command)
            if words and words[0] in parsers:
                parsers[words[0]]().parse_args(words[1:])
                checked += 1
    assert checked >= 4
