"""The pose lifter's data: simulated workers seen by simulated cameras (firmware_sim).

Recipe (:func:`build_splits`)
-----------------------------
* Subjects: heights ~ N(172, 11) cm (the dissertation's cohort), clipped to 145-200 cm,
  half "F", half "M"; every segment length is then scaled by N(1, 3 %) on its own, so
  proportions differ between people too. TRAIN subjects and HELD-OUT subjects are disjoint.
* Motions: each subject performs a random working session
  (:func:`firmware_sim.people.motions.random_activity`: walking at 0.5-2.0 m/s with turns and
  curves, standing, working at a point, looking down, bending, squatting, turning) around the
  Sawyer's work cell, at 30 Hz.
* Cameras: placements as in the dissertation (3-8 m from the cell, 1-3 m high, aimed at it;
  :func:`firmware_sim.devices.camera.random_placement`), in the canonical 100 deg pinhole camera the
  lifter serves (a distorted real camera is undistorted into it by the runtime). A pool of
  TRAIN placements and a disjoint pool of HELD-OUT placements; each session is seen from
  ``views`` placements of its pool.
* Inputs: the 2D detector model (:func:`firmware_sim.devices.camera.detect`: noise scaling with
  distance, jitter, outliers, left/right swaps, missed joints, joints out of the image),
  then the runtime's policy for missing joints: a missed joint is HELD at its last value;
  a frame is ``valid`` when every joint was seen within the last ``hold_frames`` (3)
  frames -- the frames the streaming runtime would lift -- and only valid frames are
  trained on and scored. Normalised as the model contract says (``u/w*2 - 1``, ``v/w*2 - h/w``).
* Targets: camera-frame joints (OpenCV axes, metres): ``pose3d`` root-relative (joint 0 = 0)
  and ``root3d`` the pelvis.

Splits: ``train`` (train subjects x train cameras), ``test_subjects`` (held-out subjects x
train cameras) and ``test`` (held-out subjects x held-out cameras: both unseen).

Windows (:meth:`PoseSet.windows`): frame i's causal 27-frame window, padded at the start of
its sequence by repeating the first frame, as the streaming runtime does.
"""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from edge_runtime.core import skeleton as sk
from firmware_sim.devices import camera as cam_sim
from firmware_sim.people import motions as mo
from firmware_sim.people.human import Body

LENGTH_FIELDS = ("upper_arm_m", "forearm_m", "hand_m", "thigh_m", "shank_m", "head_m", "shoulder_width_m",
                 "hip_width_m", "trunk_m", "neck_m", "crown_m")
ACTIVITY_NAMES = ("walk", "stand", "work", "look_down", "bend", "squat", "turn")


@dataclass(frozen=True)
class DataConfig:
    """How much to simulate, and how."""

    train_subjects: int = 32                 #: subjects in the training split
    test_subjects: int = 8                   #: held-out subjects
    seconds_per_subject: float = 90.0        #: length of each subject's session (s)
    train_cameras: int = 24                  #: pool of training placements
    test_cameras: int = 8                    #: pool of held-out placements
    views: int = 3                           #: placements that see each session
    rate_hz: float = 30.0                    #: camera frame rate
    hold_frames: int = 3                     #: the runtime's hold for missed joints (frames)
    noise_scale: float = 1.0                 #: multiplies the detector's noise and error rates
    seed: int = 0                            #: everything follows from it

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass
class PoseSet:
    """Frames of several sequences, concatenated (F frames)."""

    kp2d: np.ndarray          #: (F, 17, 2) float32 normalised canonical-camera keypoints, missing joints held
    pose3d: np.ndarray        #: (F, 17, 3) float32 root-relative camera-frame joints (m)
    root3d: np.ndarray        #: (F, 3) float32 pelvis in the camera frame (m)
    valid: np.ndarray         #: (F,) bool: the runtime would lift this frame
    seq_start: np.ndarray     #: (F,) int64 global index of the first frame of the frame's sequence
    subject: np.ndarray       #: (F,) int16 subject id
    camera: np.ndarray        #: (F,) int16 camera id
    activity: np.ndarray      #: (F,) int8 index into ACTIVITY_NAMES
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.kp2d)

    def windows(self, idx: np.ndarray, receptive_field: int = 27) -> np.ndarray:
        """(len(idx), rf, 17, 2) causal windows ending at the frames ``idx``, start-padded per sequence."""
        idx = np.asarray(idx)
        g = idx[:, None] - (receptive_field - 1) + np.arange(receptive_field)[None]
        g = np.maximum(g, self.seq_start[idx][:, None])
        return self.kp2d[g]

    def save(self, path: str | Path) -> None:
        """NPZ with the arrays and ``meta`` as JSON (integer keys become strings)."""
        np.savez_compressed(path, **{k: getattr(self, k) for k in _ARRAYS}, meta=np.array(json.dumps(self.meta)))

    @classmethod
    def load(cls, path: str | Path) -> "PoseSet":
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in _ARRAYS}
            meta = json.loads(str(z["meta"]))
        return cls(**arrays, meta=meta)


_ARRAYS = ("kp2d", "pose3d", "root3d", "valid", "seq_start", "subject", "camera", "activity")


def make_subject(rng: np.random.Generator, sex: str) -> Body:
    """A body of height ~ N(172, 11) cm (clipped 145-200) with every length scaled by N(1, 3 %)."""
    h = float(np.clip(rng.normal(1.72, 0.11), 1.45, 2.00))
    body = Body.from_height(h, sex)
    return dataclasses.replace(body, **{f: getattr(body, f) * float(np.clip(rng.normal(1.0, 0.03), 0.9, 1.1))
                                        for f in LENGTH_FIELDS})


def held_joints(det: np.ndarray, hold_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Detector output (T, 17, 3) -> (pixels (T, 17, 2) with missed joints held at their last value and
    never-seen joints at their first later value, valid (T,): every joint seen within ``hold_frames``)."""
    px = det[..., :2].copy()
    seen = np.isfinite(px).all(-1)
    T = len(px)
    idx = np.where(seen, np.arange(T)[:, None], -1)
    last = np.maximum.accumulate(idx, axis=0)                      # last seen frame per joint
    age = np.where(last >= 0, np.arange(T)[:, None] - last, T + 1)
    valid = (age <= hold_frames).all(1)
    nxt = np.where(seen, np.arange(T)[:, None], T)
    nxt = np.minimum.accumulate(nxt[::-1], axis=0)[::-1]           # next seen frame (for the start)
    src = np.where(last >= 0, last, np.minimum(nxt, T - 1))
    px = px[src, np.arange(17)[None]]
    px = np.nan_to_num(px, nan=0.0)                                # joints never seen at all (frames invalid)
    return px, valid


def _sequence(body: Body, motion: mo.Motion, camera: cam_sim.Camera, rng: np.random.Generator,
              noise: cam_sim.DetectorNoise, hold_frames: int) -> dict:
    det = cam_sim.detect(camera, motion.joints_m, rng, noise)
    px, valid = held_joints(det, hold_frames)
    joints_cam = camera.to_camera(motion.joints_m)
    valid &= joints_cam[:, :, 2].min(1) > 0.3                       # the whole body in front of the camera
    act = np.array([ACTIVITY_NAMES.index(a) for a in motion.labels], np.int8)
    return {"kp2d": cam_sim.to_model_input(px), "pose3d": (joints_cam - joints_cam[:, :1]).astype(np.float32),
            "root3d": joints_cam[:, 0].astype(np.float32), "valid": valid, "activity": act}


def simulate(subject_ids, camera_ids, bodies: dict, cameras: dict, cfg: DataConfig, rng: np.random.Generator,
             progress: bool = False) -> PoseSet:
    """Each subject's session seen from ``cfg.views`` cameras drawn from ``camera_ids``."""
    from tqdm import tqdm

    noise = cam_sim.DetectorNoise().scaled(cfg.noise_scale)
    parts, start = [], 0
    for s in tqdm(subject_ids, desc="simulate", unit="subject", disable=not progress, leave=False):
        motion = mo.random_activity(bodies[s], rng, cfg.seconds_per_subject, cfg.rate_hz)
        views = rng.choice(camera_ids, size=min(cfg.views, len(camera_ids)), replace=False)
        for c in views:
            d = _sequence(bodies[s], motion, cameras[int(c)], rng, noise, cfg.hold_frames)
            n = len(d["kp2d"])
            d.update(seq_start=np.full(n, start, np.int64), subject=np.full(n, s, np.int16),
                     camera=np.full(n, c, np.int16))
            parts.append(d)
            start += n
    arrays = {k: np.concatenate([p[k] for p in parts]) for k in _ARRAYS}
    return PoseSet(**arrays)


def build_splits(cfg: DataConfig = DataConfig(), progress: bool = False) -> dict[str, PoseSet]:
    """{"train", "test_subjects", "test"} as the module docstring describes; deterministic in ``cfg.seed``."""
    rng = np.random.default_rng(cfg.seed)
    n_sub = cfg.train_subjects + cfg.test_subjects
    sexes = ["F" if i % 2 else "M" for i in range(n_sub)]
    bodies = {i: make_subject(rng, sexes[i]) for i in range(n_sub)}
    n_cam = cfg.train_cameras + cfg.test_cameras
    cameras = {i: cam_sim.random_placement(rng, rate_hz=cfg.rate_hz) for i in range(n_cam)}
    train_s, test_s = list(range(cfg.train_subjects)), list(range(cfg.train_subjects, n_sub))
    train_c, test_c = list(range(cfg.train_cameras)), list(range(cfg.train_cameras, n_cam))
    meta = {"config": cfg.to_dict(),
            "subjects": {i: {"height_m": round(b.height_m, 4), "sex": b.sex} for i, b in bodies.items()},
            "cameras": {i: [round(float(v), 4) for v in c.position_m] for i, c in cameras.items()},
            "extrinsics": {i: {"R": c.R.tolist(), "t": c.t.tolist()} for i, c in cameras.items()},
            "train_subjects": train_s, "test_subjects": test_s, "train_cameras": train_c, "test_cameras": test_c}
    out = {"train": simulate(train_s, train_c, bodies, cameras, cfg, rng, progress),
           "test_subjects": simulate(test_s, train_c, bodies, cameras, cfg, rng, progress),
           "test": simulate(test_s, test_c, bodies, cameras, cfg, rng, progress)}
    for name, ps in out.items():
        ps.meta = dict(meta, split=name)
    return out


def trained_types_only(ps: PoseSet) -> PoseSet:
    """``ps`` with only the frames of the motion types trained on (``meta["train_motions"]``) valid: the
    held-out types' frames stay in the arrays (their neighbours' windows read them) but are never scored."""
    names = ps.meta.get("activity_names", ACTIVITY_NAMES)
    trained = [names.index(m) for m in ps.meta.get("train_motions", names)]
    return dataclasses.replace(ps, valid=ps.valid & np.isin(ps.activity, trained))


def flip(kp2d: np.ndarray, pose3d: np.ndarray, root3d: np.ndarray):
    """Mirror image augmentation (VideoPose3D's): x -> -x in the normalised image and in the camera frame,
    left and right joints swapped. Exact for the canonical camera (principal point at the centre)."""
    perm = np.arange(sk.N_JOINTS)
    perm[list(sk.JOINTS_LEFT)] = sk.JOINTS_RIGHT
    perm[list(sk.JOINTS_RIGHT)] = sk.JOINTS_LEFT
    sign = np.array([-1.0, 1.0], np.float32)
    k = kp2d[..., perm, :] * sign
    p = pose3d[..., perm, :] * np.array([-1.0, 1.0, 1.0], np.float32)
    r = root3d * np.array([-1.0, 1.0, 1.0], np.float32)
    return k, p, r


def summary(ps: PoseSet) -> dict:
    """Frames, valid frames, subjects, cameras and the activity mix of a split."""
    names = ps.meta.get("activity_names", ACTIVITY_NAMES)
    acts = {names[i]: int((ps.activity[ps.valid] == i).sum()) for i in range(len(names))}
    depth = ps.root3d[ps.valid, 2]
    return {"frames": len(ps), "valid_frames": int(ps.valid.sum()), "subjects": sorted({int(s) for s in ps.subject}),
            "cameras": sorted({int(c) for c in ps.camera}), "activities": acts,
            "root_depth_m": {"median": float(np.median(depth)) if depth.size else math.nan,
                             "p5": float(np.percentile(depth, 5)) if depth.size else math.nan,
                             "p95": float(np.percentile(depth, 95)) if depth.size else math.nan}}


# --------------------------------------------------------------------------- varied motion (issue 14)
@dataclass(frozen=True)
class VariedConfig:
    """The recipe that generalises (:func:`build_varied_splits`): the motion types of
    :mod:`firmware_sim.scenarios.recording`, a real detector's 2D errors, distorted lenses."""

    train_scenes: int = 120                  #: training scenes (one camera, ``people`` people each)
    val_scenes: int = 12                     #: validation scenes (held-out cameras; every choice is made here)
    test_scenes: int = 12                    #: test scenes (other held-out cameras; scored once)
    seconds_per_scene: float = 60.0
    people: int = 2                          #: people per training scene (they hide each other)
    eval_people: int = 3                     #: people per validation / test scene (as the perception scenes)
    train_cameras: int = 60                  #: pool of training placements
    eval_cameras: int = 10                   #: pool size of the validation placements, and of the test ones
    holdout_motions: tuple[str, ...] = ("carry", "reach")   #: never in training; scored in val and test
    real_noise_share: float = 0.8            #: training scenes with a real detector's errors (the rest: default)
    real_noise_scale: tuple[float, float] = (0.6, 1.4)      #: REAL_DETECTOR scaled by U(lo, hi) per scene
    rate_hz: float = 30.0
    hold_frames: int = 3
    min_score: float = 0.3                   #: the runtime's LifterParams.min_score
    random_limbs_share: float = 0.0          #: training people whose limbs also move at random (pose-space augmentation)
    seed: int = 0

    def __post_init__(self):
        if not 0.0 <= self.random_limbs_share <= 1.0:
            raise ValueError(f"random_limbs_share: expected 0-1, got {self.random_limbs_share!r}")

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["holdout_motions"] = list(self.holdout_motions)
        d["real_noise_scale"] = list(self.real_noise_scale)
        d["recipe"] = "varied"
        return d


def varied_body(rng: np.random.Generator) -> Body:
    """A body 1.45-2.0 m tall (uniform: the extremes matter as much as the middle), either sex,
    every segment scaled by N(1, 3 %) on its own."""
    from firmware_sim.scenarios.recording import HEIGHTS_M

    body = Body.from_height(float(rng.uniform(*HEIGHTS_M)), str(rng.choice(["F", "M"])))
    return dataclasses.replace(body, **{f: getattr(body, f) * float(np.clip(rng.normal(1.0, 0.03), 0.9, 1.1))
                                        for f in LENGTH_FIELDS})


RANDOM_LIMBS_P_ACTIVE = 0.5
"""Share of the time each limb group of an augmented person follows its random trajectory (set a priori, not tuned)."""


def limb_augmenter(share: float, rng: np.random.Generator):
    """``motion_fn`` for :func:`firmware_sim.scenarios.recording.scene`: each person, with probability
    ``share``, gets :func:`firmware_sim.people.motions.random_limbs` on top of the scripted session.
    Draws only from ``rng`` (its own generator), so the scene's other draws are the same with it or without."""
    def fn(m: mo.Motion) -> mo.Motion:
        return mo.random_limbs(m, rng, RANDOM_LIMBS_P_ACTIVE) if rng.random() < share else m
    return fn


def _scene_sequences(camera, rng, cfg: VariedConfig, people: int, noise, kinds, names, motion_fn=None) -> list[dict]:
    """One scene's people as training sequences: COCO detector output with occlusion, mapped to
    H36M as the runtime maps it, low scores missing, missed joints held, undistorted into the
    canonical camera and normalised; targets in the camera frame."""
    from edge_runtime.robot.keypoints import to_h36m
    from firmware_sim.scenarios.recording import scene

    sc = scene(camera, rng, cfg.seconds_per_scene, people, noise, kinds, body_fn=varied_body, motion_fn=motion_fn)
    out = []
    for m, kp in zip(sc["motions"], sc["keypoints"]):
        h = to_h36m(kp, "coco")
        h[~(h[..., 2] >= cfg.min_score)] = np.nan
        px, valid = held_joints(h, cfg.hold_frames)
        joints_cam = camera.to_camera(m.joints_m)
        valid &= joints_cam[:, :, 2].min(1) > 0.3
        out.append({"kp2d": cam_sim.to_model_input(px, camera),
                    "pose3d": (joints_cam - joints_cam[:, :1]).astype(np.float32),
                    "root3d": joints_cam[:, 0].astype(np.float32), "valid": valid,
                    "activity": np.array([names.index(a) for a in m.labels], np.int8)})
    return out


def _varied_split(n_scenes: int, camera_ids, cameras: dict, cfg: VariedConfig, rng, people: int, kinds,
                  train: bool, person0: int, progress: bool) -> PoseSet:
    from tqdm import tqdm

    from firmware_sim.scenarios.recording import MOTIONS

    # the augmentation has its own generator: validation and test (drawn after training from ``rng``)
    # are the same scenes with it or without
    motion_fn = (limb_augmenter(cfg.random_limbs_share, np.random.default_rng([cfg.seed, 24]))
                 if train and cfg.random_limbs_share > 0 else None)
    parts, start, person = [], 0, person0
    for _ in tqdm(range(n_scenes), desc="simulate", unit="scene", disable=not progress, leave=False):
        c = int(rng.choice(camera_ids))
        noise = cam_sim.REAL_DETECTOR
        if train:   # a spread of detectors: real ones better and worse than REAL_DETECTOR, and the default
            noise = (cam_sim.REAL_DETECTOR.scaled(float(rng.uniform(*cfg.real_noise_scale)))
                     if rng.random() < cfg.real_noise_share else cam_sim.DetectorNoise())
        for d in _scene_sequences(cameras[c], rng, cfg, people, noise, kinds, MOTIONS, motion_fn):
            n = len(d["kp2d"])
            d.update(seq_start=np.full(n, start, np.int64), subject=np.full(n, person, np.int16),
                     camera=np.full(n, c, np.int16))
            parts.append(d)
            start += n
            person += 1
    return PoseSet(**{k: np.concatenate([p[k] for p in parts]) for k in _ARRAYS})


def build_varied_splits(cfg: VariedConfig = VariedConfig(), progress: bool = False) -> dict[str, PoseSet]:
    """{"train", "val", "test"}: every person is a new body (no one is in two splits); the three
    splits see the cell from three disjoint pools of placements with distorted wide-angle lenses
    (:func:`firmware_sim.scenarios.recording.random_camera`); training never holds the motion
    types ``cfg.holdout_motions``, validation and test hold every type. Validation and test are
    at REAL_DETECTOR's errors. With ``cfg.random_limbs_share`` that share of the training people
    also move their arms, trunk, neck and legs along random trajectories through their ranges of
    motion (:func:`firmware_sim.people.motions.random_limbs`); validation and test are unchanged by
    it. Deterministic in ``cfg.seed``."""
    from firmware_sim.scenarios.recording import MOTIONS, random_camera

    unknown = set(cfg.holdout_motions) - set(MOTIONS)
    if unknown:
        raise ValueError(f"holdout_motions: {sorted(unknown)} are not motion types ({', '.join(MOTIONS)})")
    rng = np.random.default_rng(cfg.seed)
    n_cam = cfg.train_cameras + 2 * cfg.eval_cameras
    cameras = {i: random_camera(rng) for i in range(n_cam)}
    pools = {"train": list(range(cfg.train_cameras)),
             "val": list(range(cfg.train_cameras, cfg.train_cameras + cfg.eval_cameras)),
             "test": list(range(cfg.train_cameras + cfg.eval_cameras, n_cam))}
    train_kinds = tuple(k for k in MOTIONS if k not in cfg.holdout_motions)
    meta = {"config": cfg.to_dict(), "activity_names": list(MOTIONS), "train_motions": list(train_kinds),
            "cameras": {i: [round(float(v), 4) for v in c.position_m] for i, c in cameras.items()},
            "extrinsics": {i: {"R": c.R.tolist(), "t": c.t.tolist()} for i, c in cameras.items()},
            **{f"{k}_cameras": v for k, v in pools.items()}}
    out = {"train": _varied_split(cfg.train_scenes, pools["train"], cameras, cfg, rng, cfg.people, train_kinds,
                                  True, 0, progress)}
    out["val"] = _varied_split(cfg.val_scenes, pools["val"], cameras, cfg, rng, cfg.eval_people, MOTIONS, False,
                               10_000, progress)
    out["test"] = _varied_split(cfg.test_scenes, pools["test"], cameras, cfg, rng, cfg.eval_people, MOTIONS, False,
                                20_000, progress)
    for name, ps in out.items():
        ps.meta = dict(meta, split=name)
    return out
