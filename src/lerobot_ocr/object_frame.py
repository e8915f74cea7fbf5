"""Express robot vectors (actions, proprioception) in an object frame and back: OCR's "zero-out".

A `FrameSpec` says how the leading numbers of a vector live in space; the rest pass through
unchanged (e.g. a gripper command):
- "point":            the first d numbers are a world position (Push-T's target agent xy, an EEF xyz);
- "pose:<rotation>":  the first numbers are a pose in that representation ("angle" for SE(2),
                      "quat_wxyz", "quat_xyzw", "axis_angle", "rot6d" for SE(3));
- "none":             nothing is transformed (e.g. joint-space actions).

In the object frame, rotations are written continuously: SE(2) angles as (cos, sin), SE(3)
rotations as rot6d, so a learned model never sees a wrap-around. `to_object_frame` and
`from_object_frame` are exact inverses (up to float error) for the same transform.

Shapes: values (..., N) world; transform (..., d+1, d+1) world-from-object (broadcasts over the
leading dims); object-frame values (..., N') with N' = `spec.object_size(N, d)`.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from lerobot_ocr.geometry import compose, invert, matrix_to_pose, pose_size, pose_to_matrix, transform_points
from lerobot_ocr.geometry.rigid import make_transform
from lerobot_ocr.geometry.rotations import matrix_to_rotation_6d, rotation_6d_to_matrix

KINDS = ("point", "pose", "none")


@dataclass(frozen=True)
class FrameSpec:
    """How a vector's leading numbers transform under a change of object frame (see module doc)."""

    kind: str = "point"
    rotation: str | None = None

    @classmethod
    def parse(cls, spec: str | FrameSpec) -> FrameSpec:
        """A spec string ("point", "none", "pose:<rotation>") or a FrameSpec -> a FrameSpec.

        Raises:
            ValueError: an unknown spec.
        """
        if isinstance(spec, FrameSpec):
            return spec
        kind, _, rotation = str(spec).partition(":")
        if kind not in KINDS or (kind == "pose") != bool(rotation):
            raise ValueError(
                f"Unknown frame spec {spec!r}. Use 'point', 'none', or 'pose:<rotation>' with rotation one "
                "of angle, quat_wxyz, quat_xyzw, axis_angle, rot6d (e.g. 'pose:axis_angle')."
            )
        if rotation:
            pose_size(rotation)  # validates the representation
        return cls(kind, rotation or None)

    def world_size(self, dim: int) -> int:
        """Numbers of the vector that are transformed (the rest pass through)."""
        if self.kind == "none":
            return 0
        return dim if self.kind == "point" else pose_size(self.rotation)

    def object_size(self, n: int, dim: int) -> int:
        """Length N' in the object frame of a length-n world vector."""
        if self.kind != "pose":
            return n
        rot_size = 2 if dim == 2 else 6  # (cos, sin) or rot6d
        return n - self.world_size(dim) + dim + rot_size

    def check(self, n: int, dim: int, name: str) -> None:
        """Check that a vector of `n` numbers fits this spec for a `dim`-D object (`name`: for the error).

        Raises:
            ValueError: a spec that does not fit the object's dimension or the vector's size.
        """
        if self.kind == "pose" and (2 if self.rotation == "angle" else 3) != dim:
            raise ValueError(f"{name} frame spec 'pose:{self.rotation}' does not fit a {dim}D object pose.")
        if n < self.world_size(dim):
            raise ValueError(
                f"{name} has {n} numbers but frame spec "
                f"{self.kind}{':' + self.rotation if self.rotation else ''} needs at least "
                f"{self.world_size(dim)} for a {dim}D object. Fix the spec or the feature."
            )


def _rotation_to_continuous(rot: torch.Tensor) -> torch.Tensor:
    if rot.shape[-1] == 2:
        return torch.stack((rot[..., 0, 0], rot[..., 1, 0]), dim=-1)  # (cos, sin)
    return matrix_to_rotation_6d(rot)


def _continuous_to_rotation(x: torch.Tensor, dim: int) -> torch.Tensor:
    if dim == 2:
        c, s = x.unbind(-1)
        norm = torch.sqrt(c * c + s * s).clamp_min(1e-12)  # a model's output need not be unit length
        c, s = c / norm, s / norm
        return torch.stack((torch.stack((c, -s), -1), torch.stack((s, c), -1)), -2)
    return rotation_6d_to_matrix(x)


def to_object_frame(values: torch.Tensor, transform: torch.Tensor, spec: str | FrameSpec) -> torch.Tensor:
    """World vectors (..., N) -> object-frame vectors (..., N'), by transform^-1 (world-from-object)."""
    spec = FrameSpec.parse(spec)
    dim = transform.shape[-1] - 1
    spec.check(values.shape[-1], dim, "values")
    if spec.kind == "none":
        return values
    inv = invert(transform.to(values.dtype))
    n = spec.world_size(dim)
    head, rest = values[..., :n], values[..., n:]
    if spec.kind == "point":
        head = transform_points(inv, head.unsqueeze(-2)).squeeze(-2)
    else:
        local = compose(inv, pose_to_matrix(head, spec.rotation))
        head = torch.cat((local[..., :dim, dim], _rotation_to_continuous(local[..., :dim, :dim])), dim=-1)
    return torch.cat((head, rest), dim=-1)


def from_object_frame(values: torch.Tensor, transform: torch.Tensor, spec: str | FrameSpec) -> torch.Tensor:
    """Object-frame vectors (..., N') -> world vectors (..., N), by transform (world-from-object)."""
    spec = FrameSpec.parse(spec)
    dim = transform.shape[-1] - 1
    if spec.kind == "none":
        return values
    t = transform.to(values.dtype)
    if spec.kind == "point":
        head = transform_points(t, values[..., :dim].unsqueeze(-2)).squeeze(-2)
        return torch.cat((head, values[..., dim:]), dim=-1)
    n = dim + (2 if dim == 2 else 6)
    pos, rot = values[..., :dim], _continuous_to_rotation(values[..., dim:n], dim)
    world = compose(t, make_transform(rot, pos))
    return torch.cat((matrix_to_pose(world, spec.rotation), values[..., n:]), dim=-1)
