"""VideoPose3D's temporal convolutional pose lifter in one file (after its ``common/model.py``).

Pavllo et al., "3D human pose estimation in video with temporal convolutions and
semi-supervised training", CVPR 2019. A 2D keypoint sequence (N, T, J_in, 2) goes through

    expand:  Conv1d(J_in*2 -> C, width w0) -> BatchNorm -> ReLU -> Dropout
    blocks:  for i = 1..B:  x = slice(x) + Drop(ReLU(BN(Conv1x1(Drop(ReLU(BN(Conv_wi,dil(x))))))))
    shrink:  Conv1d(C -> J_out*3, 1)

with dilations w0, w0*w1, ... so that filter widths (3, 3, 3) see 27 frames (the receptive
field is the product of the widths). Convolutions before a BatchNorm have no bias. Counts
with 17 joints in and out and widths (3, 3, 3) (:func:`count_parameters`):

* channels 1024: 8,555,571 parameters (VideoPose3D's 27-frame model, 48.8 mm on Human3.6M)
* channels  512: 2,180,659
* channels  256:   566,067 (53.7 mm on Human3.6M in the paper's ablation)

Two equivalent implementations share the weights (same parameter names and shapes):

* :class:`TemporalModel` -- dilated convolutions: any sequence length T >= 27 in,
  T - 26 poses out (one per window). Used for sequences and to test causality.
* :class:`TemporalModelOptimized1f` -- the strided variant VideoPose3D trains with: stride =
  width instead of dilation, exactly one pose per 27-frame window, ~3x fewer operations.
  Used for training and for the exported ONNX (the runtime feeds exactly 27 frames).

Causal mode (``causal=True``): a window's output describes its LAST frame, so the model
uses only past frames (a streaming camera cannot wait for the future); the residual
connections take the last rather than the centre element of each span. Non-causal: the
centre frame.

Input conditioning (:func:`condition_input`, no parameters): joint 0 keeps its image position,
the other joints become offsets from it, scaled by 4 -- a linear map the first layer could
learn, made explicit because it speeds CPU training a lot.

Root position (:class:`LifterNet`): VideoPose3D's trajectory model -- a second temporal
network on the same 2D input regressing the pelvis's camera-frame position (x, y, z),
trained with a 1/z-weighted loss (far people count less: their depth is inherently less
certain). We chose it over a ground-plane method (intersecting the ankle rays with the
floor) because it needs no camera extrinsics at inference time -- the contract's root is
in the camera frame and the runtime's robot-frame calibration comes later -- and it keeps
working when the feet are out of the image or off the floor (squatting, stepping). Its
width ``trajectory_channels`` defaults to 256: depth from apparent size needs little
capacity, and it keeps the 1024-channel asset under the 10 MB edge budget.

:class:`LifterNet` outputs ``pose_3d`` (N, 1, 17, 3), root-relative (joint 0 is exactly 0),
and ``root_3d`` (N, 1, 3), both in metres in the camera frame (OpenCV axes), for the last
(causal) or centre frame of a 27-frame window -- the model contract of the manifest.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

N_JOINTS = 17
DEFAULT_FILTER_WIDTHS = (3, 3, 3)
RELATIVE_SCALE = 4.0         # joint offsets from the pelvis are scaled to ~unit size (condition_input)
INITIAL_DEPTH_M = 5.0        # the trajectory network's initial depth output (bias), a typical camera distance


@dataclass(frozen=True)
class LifterConfig:
    """The architecture of a :class:`LifterNet`."""

    channels: int = 256                         #: width of the pose network
    filter_widths: tuple[int, ...] = DEFAULT_FILTER_WIDTHS   #: one per layer; receptive field = product
    dropout: float = 0.25                       #: VideoPose3D's default
    causal: bool = True                         #: describe the last frame of the window (streaming)
    trajectory_channels: int = 256              #: width of the root-position network (0: none)
    joints: int = N_JOINTS                      #: joints in and out

    @property
    def receptive_field(self) -> int:
        rf = 1
        for w in self.filter_widths:
            rf *= w
        return rf

    def to_dict(self) -> dict:
        d = asdict(self)
        d["filter_widths"] = list(self.filter_widths)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "LifterConfig":
        d = dict(d)
        d["filter_widths"] = tuple(d["filter_widths"])
        return cls(**d)


class TemporalModelBase(nn.Module):
    """Both variants: the layers, padding and causal shifts, the residual blocks; a variant only
    says whether it is strided."""

    STRIDED: bool  #: set by each variant

    def __init__(self, joints_in: int, in_features: int, joints_out: int, filter_widths, causal: bool = False,
                 dropout: float = 0.25, channels: int = 1024):
        super().__init__()
        for w in filter_widths:
            assert w % 2 == 1, "only odd filter widths are supported"
        self.joints_in, self.in_features, self.joints_out = joints_in, in_features, joints_out
        self.filter_widths = tuple(filter_widths)
        self.drop = nn.Dropout(dropout)
        self.relu = nn.ReLU(inplace=True)
        self.pad = [filter_widths[0] // 2]
        self.expand_bn = nn.BatchNorm1d(channels, momentum=0.1)
        self.shrink = nn.Conv1d(channels, joints_out * 3, 1)
        self.causal = causal
        self._build_layers(joints_in, in_features, filter_widths, causal, channels, strided=self.STRIDED)

    def _build_layers(self, joints_in: int, in_features: int, filter_widths, causal: bool, channels: int,
                      strided: bool) -> None:
        """expand_conv and the residual blocks: dilated convolutions, or (``strided``) the same
        weights applied with stride = width, one output per window. Same names and shapes
        either way, so one state dict serves both variants."""
        w0 = filter_widths[0]
        self.expand_conv = nn.Conv1d(joints_in * in_features, channels, w0, stride=w0 if strided else 1, bias=False)
        convs, bns = [], []
        self.causal_shift = [w0 // 2 if causal else 0]
        dilation = w0
        for w in filter_widths[1:]:
            self.pad.append((w - 1) * dilation // 2)
            self.causal_shift.append(((w // 2) if strided else (w // 2) * dilation) if causal else 0)
            convs.append(nn.Conv1d(channels, channels, w, stride=w, bias=False) if strided
                         else nn.Conv1d(channels, channels, w, dilation=dilation, bias=False))
            bns.append(nn.BatchNorm1d(channels, momentum=0.1))
            convs.append(nn.Conv1d(channels, channels, 1, bias=False))
            bns.append(nn.BatchNorm1d(channels, momentum=0.1))
            dilation *= w
        self.layers_conv = nn.ModuleList(convs)
        self.layers_bn = nn.ModuleList(bns)

    def receptive_field(self) -> int:
        return 1 + 2 * sum(self.pad)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, T, J_in, F) -> (N, T - receptive_field + 1, J_out, 3)."""
        n, t = x.shape[:2]
        x = x.reshape(n, t, -1).permute(0, 2, 1)
        x = self._forward_blocks(x)
        return x.permute(0, 2, 1).reshape(n, -1, self.joints_out, 3)


    def _forward_blocks(self, x: torch.Tensor) -> torch.Tensor:
        x = self.drop(self.relu(self.expand_bn(self.expand_conv(x))))
        for i in range(len(self.pad) - 1):
            res = self._residual(x, i)
            x = self.drop(self.relu(self.layers_bn[2 * i](self.layers_conv[2 * i](x))))
            x = res + self.drop(self.relu(self.layers_bn[2 * i + 1](self.layers_conv[2 * i + 1](x))))
        return self.shrink(x)

    def _residual(self, x: torch.Tensor, i: int) -> torch.Tensor:
        """The frames of ``x`` that residual block ``i``'s output lines up with."""
        shift = self.causal_shift[i + 1]
        if self.STRIDED:
            w = self.filter_widths[i + 1]
            return x[:, :, shift + w // 2:: w]
        pad = self.pad[i + 1]
        return x[:, :, pad + shift: x.shape[2] - pad + shift]


class TemporalModel(TemporalModelBase):
    """Dilated temporal convolutions: a sequence of T frames in, T - rf + 1 poses out."""

    STRIDED = False


class TemporalModelOptimized1f(TemporalModelBase):
    """The strided variant: exactly one output per receptive-field window (training and export)."""

    STRIDED = True


def condition_input(x: torch.Tensor) -> torch.Tensor:
    """A fixed, parameter-free linear change of the 2D input (N, T, J, 2): joint 0 keeps its normalised image
    position, every other joint becomes its offset from joint 0 times :data:`RELATIVE_SCALE`.

    A linear map of the input is something the first convolution could learn itself, so the model family is
    VideoPose3D's; but a worker 4-8 m away spans only ~0.2 normalised units while his position spans ~2, and
    without this the network spends most of a CPU training budget learning to subtract the position. Depth
    (apparent size) and the viewing ray (position in the wide-angle image) are both kept."""
    root = x[:, :, :1]
    return torch.cat([root, (x[:, :, 1:] - root) * RELATIVE_SCALE], dim=2)


def count_parameters(module: nn.Module) -> int:
    """Trainable parameters (BatchNorm running statistics are buffers, not counted)."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


class LifterNet(nn.Module):
    """Pose network + trajectory (root) network on the same 2D input: the shipped lifter.

    ``forward(keypoints_2d (N, T, 17, 2))`` -> ``(pose_3d (N, T', 17, 3), root_3d (N, T', 3))`` with
    T' = T - 26 for ``strided=False`` and T' = 1 for ``strided=True`` (T must then be 27)."""

    def __init__(self, config: LifterConfig = LifterConfig(), strided: bool = True):
        super().__init__()
        self.config = config
        cls = TemporalModelOptimized1f if strided else TemporalModel
        c = config
        self.pose = cls(c.joints, 2, c.joints, c.filter_widths, c.causal, c.dropout, c.channels)
        self.trajectory = (cls(c.joints, 2, 1, c.filter_widths, c.causal, c.dropout, c.trajectory_channels)
                           if c.trajectory_channels else None)
        if self.trajectory is not None:      # start from a typical camera distance instead of z = 0
            with torch.no_grad():
                self.trajectory.shrink.bias[2] = INITIAL_DEPTH_M

    def forward(self, keypoints_2d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        keypoints_2d = condition_input(keypoints_2d)
        pose = self.pose(keypoints_2d)
        pose = pose - pose[:, :, :1]                       # root-relative: joint 0 is exactly 0
        if self.trajectory is None:
            root = torch.zeros(pose.shape[:2] + (3,), dtype=pose.dtype, device=pose.device)
        else:
            root = self.trajectory(keypoints_2d)[:, :, 0]
        return pose, root

    def parameter_counts(self) -> dict:
        """{"pose", "trajectory", "total"} trainable parameters."""
        p = count_parameters(self.pose)
        t = count_parameters(self.trajectory) if self.trajectory is not None else 0
        return {"pose": p, "trajectory": t, "total": p + t}

    def as_variant(self, strided: bool) -> "LifterNet":
        """The same weights in the other implementation (dilated <-> strided)."""
        other = LifterNet(self.config, strided=strided)
        other.load_state_dict(self.state_dict())
        return other.train(self.training)


def mpjpe(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean per-joint position error (same units as the inputs), averaged over everything but the last axis."""
    return torch.linalg.vector_norm(pred - target, dim=-1).mean()


def weighted_mpjpe(pred: torch.Tensor, target: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """VideoPose3D's weighted MPJPE: mean of w * ||pred - target||, ``w`` broadcast over the points."""
    return (w * torch.linalg.vector_norm(pred - target, dim=-1)).mean()


def build_from_manifest(entry: dict) -> LifterNet:
    """An untrained :class:`LifterNet` (strided, eval mode) with the architecture a manifest entry records
    (its ``config``, written by ``python -m export lifter``); used by ``python -m bench`` for torch timings."""
    cfg = entry.get("config")
    if not isinstance(cfg, dict):
        raise ValueError(f"manifest entry {entry.get('name')!r}: field 'config': missing (not a lifter entry?)")
    return LifterNet(LifterConfig.from_dict(cfg), strided=True).eval()
