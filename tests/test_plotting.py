import numpy as np
import pytest

from lerobot_ocr.keypoints import axis_tip_keypoints, pose_to_keypoints
from lerobot_ocr.manifold import KeypointManifold
from lerobot_ocr.plotting import density_field, plot_density_field, video_frame_strip


def _upright_poses(xy: np.ndarray, yaw: np.ndarray, z: float) -> np.ndarray:
    t = np.tile(np.eye(4), (len(xy), 1, 1))
    c, s = np.cos(yaw), np.sin(yaw)
    t[:, 0, 0], t[:, 0, 1], t[:, 1, 0], t[:, 1, 1] = c, -s, s, c
    t[:, :2, 3], t[:, 2, 3] = xy, z
    return t


def test_density_field_3d_object_on_a_table(tmp_path):
    """3D keypoints (a nut lying on a table): the field is high over the demos' box, arrows point to it."""
    rng = np.random.default_rng(0)
    local = axis_tip_keypoints(0.05)
    xy = np.stack([rng.uniform(-0.12, -0.10, 400), rng.uniform(0.10, 0.22, 400)], -1)
    kps = pose_to_keypoints(_upright_poses(xy, rng.uniform(-0.3, 0.3, 400), 0.83), local)
    manifold = KeypointManifold(n_components=2, random_state=0).fit(kps)
    extent = (-0.3, 0.3, -0.3, 0.4)
    field = density_field(manifold, local, 0.0, extent, resolution=25, height=0.83)
    assert field["score"].shape == (25, 25) and field["vector"].shape == (25, 25, 2)
    iy_in, ix_in = np.argmin(abs(field["ys"] - 0.16)), np.argmin(abs(field["xs"] + 0.11))
    iy_out = np.argmin(abs(field["ys"] + 0.2))
    assert not field["is_ood"][iy_in, ix_in] and field["is_ood"][iy_out, ix_in]
    # From the other side of the table (y = -0.2) recovery points toward +y, where the demos are.
    v = field["vector"][iy_out, ix_in]
    assert v[1] > 0 and abs(v[1]) > abs(v[0])
    # The same object at the wrong height is out of distribution everywhere.
    assert (
        field["is_ood"].sum()
        < density_field(manifold, local, 0.0, extent, resolution=25, height=1.2)["is_ood"].sum()
    )
    png = plot_density_field(
        manifold,
        local,
        tmp_path / "nut.png",
        extent=extent,
        height=0.83,
        resolution=20,
        regions={"ID": (-0.12, -0.10, 0.10, 0.22)},
        training_keypoints=kps,
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_video_frame_strip_picks_evenly_spaced_frames(tmp_path):
    av = pytest.importorskip("av")
    video = tmp_path / "v.mp4"
    with av.open(str(video), "w") as container:
        stream = container.add_stream("libx264", rate=10)
        stream.width, stream.height, stream.pix_fmt = 64, 48, "yuv420p"
        for i in range(20):
            frame = np.full((48, 64, 3), 12 * i, dtype=np.uint8)
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    png = video_frame_strip(video, tmp_path / "strip.png", n_frames=4, title="t")
    import matplotlib.image

    img = matplotlib.image.imread(png)
    assert img.shape[1] > 3 * img.shape[0]  # one row of 4 frames
    with pytest.raises(FileNotFoundError):
        video_frame_strip(tmp_path / "missing.mp4", tmp_path / "x.png")
