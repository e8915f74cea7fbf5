"""Object pose from an ArUco marker: OpenCV's `ArucoDetector` (subpixel corners) and `solvePnP`.

OpenCV 4.7+ has no `estimatePoseSingleMarkers`; `solvePnP(..., SOLVEPNP_IPPE_SQUARE)` on the four corners is
its replacement (`FRANKA_AND_CONTINUAL.md` §3.2). Frames: camera (OpenCV: x right, y down, z forward),
marker (x right, y up on the printed face, z out of it, origin at its centre), robot base.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def marker_corners(length: float) -> np.ndarray:
    """(4, 3) corners of a marker of side `length` (m) in its own frame, in ArUco's order TL, TR, BR, BL."""
    h = length / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def load_intrinsics(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """JSON {"K": 3x3, "dist": [...]} -> (K (3, 3), dist (n,)).

    Raises:
        ValueError: a missing key or a K that is not 3x3.
    """
    data = json.loads(Path(path).read_text())
    if "K" not in data:
        raise ValueError(f"{path}: camera intrinsics need 'K' (3x3, pixels) and optionally 'dist'.")
    K = np.asarray(data["K"], dtype=np.float64)
    if K.shape != (3, 3):
        raise ValueError(f"{path}: 'K' must be 3x3, got shape {K.shape}.")
    return K, np.asarray(data.get("dist", [0.0] * 5), dtype=np.float64)


def load_transform(path: str | Path) -> np.ndarray:
    """JSON 4x4 (a list of rows, or {"T": rows}) -> (4, 4).

    Raises:
        ValueError: not 4x4, or a bottom row other than [0, 0, 0, 1].
    """
    data = json.loads(Path(path).read_text())
    T = np.asarray(data["T"] if isinstance(data, dict) else data, dtype=np.float64)
    if T.shape != (4, 4) or not np.allclose(T[3], [0, 0, 0, 1]):
        raise ValueError(
            f"{path}: expected a 4x4 homogeneous transform (last row 0 0 0 1), got {T.tolist()}."
        )
    return T


class ArucoPoseSource:
    """`estimate(images, robot_state)` -> (4, 4) robot-base-from-object, or None when the marker is not seen.

    Args: camera (key of the robot's cameras), dictionary (e.g. "DICT_4X4_50"), marker_id, marker_length
    (m), K (3, 3) and dist (camera intrinsics), camera_pose (4, 4) base-from-camera, marker_to_object
    (4, 4) marker-from-object (None: identity). Images are RGB (LeRobot's cameras' default).

    Raises (at construction):
        ValueError: an unknown dictionary name.
    """

    def __init__(
        self,
        camera: str,
        dictionary: str,
        marker_id: int,
        marker_length: float,
        K: np.ndarray,
        dist: np.ndarray,
        camera_pose: np.ndarray | None = None,
        marker_to_object: np.ndarray | None = None,
    ):
        import cv2

        if not hasattr(cv2.aruco, dictionary):
            raise ValueError(f"unknown ArUco dictionary {dictionary!r}; e.g. DICT_4X4_50, DICT_5X5_100.")
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self._detector = cv2.aruco.ArucoDetector(
            cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)), params
        )
        self.camera, self.marker_id, self.marker_length = camera, marker_id, marker_length
        self.K, self.dist = np.asarray(K, dtype=np.float64), np.asarray(dist, dtype=np.float64)
        self.camera_pose = np.eye(4) if camera_pose is None else np.asarray(camera_pose, dtype=np.float64)
        self.marker_to_object = np.eye(4) if marker_to_object is None else np.asarray(marker_to_object)

    def camera_from_marker(self, image: np.ndarray) -> np.ndarray | None:
        """(H, W, 3) RGB uint8 -> (4, 4) camera-from-marker, or None when the marker is not detected."""
        import cv2

        gray = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)
        corners, ids, _ = self._detector.detectMarkers(gray)
        if ids is None or self.marker_id not in ids.ravel():
            return None
        found = corners[int(np.flatnonzero(ids.ravel() == self.marker_id)[0])].reshape(4, 2)
        ok, rvec, tvec = cv2.solvePnP(
            marker_corners(self.marker_length), found, self.K, self.dist, flags=cv2.SOLVEPNP_IPPE_SQUARE
        )
        if not ok:
            return None
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = cv2.Rodrigues(rvec)[0], tvec.ravel()
        return T

    def estimate(self, images: dict, robot_state: dict) -> np.ndarray | None:
        if self.camera not in images:
            raise KeyError(
                f"the ArUco pose source reads camera {self.camera!r}, but the robot's cameras are "
                f"{sorted(images)}: set --robot.pose_source.camera to one of them."
            )
        T = self.camera_from_marker(images[self.camera])
        return None if T is None else self.camera_pose @ T @ self.marker_to_object
