"""The simulated body (firmware_sim/people/human.py): lengths from height, angles, placement, ranges of motion."""
import numpy as np
import pytest

from edge_runtime.core import skeleton as sk
from firmware_sim.people.human import (
    N_ANGLES,
    ROM_DEG,
    VECTOR_FIELDS,
    Body,
    Posture,
    PostureError,
    bone_lengths,
    facing,
    heading_towards,
    joints,
    joints_from_angles,
    joints_seq,
)

FLOOR = -sk.BASE_HEIGHT_M


def _angle_deg(u, v):
    u, v = np.asarray(u, float), np.asarray(v, float)
    return np.degrees(np.arccos(np.clip(u @ v / np.linalg.norm(u) / np.linalg.norm(v), -1, 1)))


def _random_angles(rng, n):
    lo = np.array([ROM_DEG[f.split(".")[0]][0] for f in VECTOR_FIELDS])
    hi = np.array([ROM_DEG[f.split(".")[0]][1] for f in VECTOR_FIELDS])
    return rng.uniform(lo, hi, size=(n, N_ANGLES))


@pytest.mark.parametrize("height,sex", [(1.50, "F"), (1.72, "M"), (1.95, "M")])
def test_standing_heights_follow_the_height_fractions(height, sex):
    body = Body.from_height(height, sex)
    j = joints(body, Posture())
    above = j[:, 1] - FLOOR
    for idx, frac in ((sk.L_SHOULDER, 0.818), (sk.R_SHOULDER, 0.818), (sk.L_HIP, 0.530), (sk.HIP, 0.530),
                      (sk.R_KNEE, 0.285), (sk.L_ELBOW, 0.630), (sk.HEAD, 1.0)):
        assert above[idx] == pytest.approx(frac * height, abs=0.003 * height), sk.JOINTS[idx]
    assert above[sk.L_ANKLE] == pytest.approx(body.ankle_height_m)
    # the sex changes only the widths
    other = Body.from_height(height, "M" if sex == "F" else "F")
    assert other.forearm_m == body.forearm_m and other.shoulder_width_m != body.shoulder_width_m


def test_bone_lengths_do_not_change_with_posture_or_placement():
    body = Body.from_height(1.68, "F")
    rng = np.random.default_rng(0)
    ang = _random_angles(rng, 200)
    j = joints_from_angles(body, ang, rng.uniform(-3, 3, (200, 2)), rng.uniform(-np.pi, np.pi, 200))
    lengths = bone_lengths(j)
    assert np.allclose(lengths, lengths[0], atol=1e-9)
    by_child = dict(zip([c for _, c in sk.bones()], lengths[0]))
    assert by_child[sk.L_ELBOW] == pytest.approx(body.upper_arm_m)
    assert by_child[sk.R_WRIST] == pytest.approx(body.forearm_m)
    assert by_child[sk.L_KNEE] == pytest.approx(body.thigh_m)
    assert by_child[sk.R_ANKLE] == pytest.approx(body.shank_m)


@pytest.mark.parametrize("deg", [10.0, 35.0, 80.0])
def test_joint_angles_can_be_measured_back_from_the_joints(deg):
    body = Body.from_height(1.8)
    up = np.array([0.0, 1.0, 0.0])
    j = joints(body, Posture(trunk_flexion_deg=deg))
    assert _angle_deg(j[sk.THORAX] - j[sk.HIP], up) == pytest.approx(deg, abs=1e-6)
    assert j[sk.THORAX, 2] > 0                      # forward = +z at heading 0
    j = joints(body, Posture(elbow_flexion_deg=(deg, 0.0), shoulder_flexion_deg=(0.0, deg)))
    assert _angle_deg(j[sk.L_ELBOW] - j[sk.L_SHOULDER], j[sk.L_WRIST] - j[sk.L_ELBOW]) == pytest.approx(deg)
    assert _angle_deg(j[sk.R_ELBOW] - j[sk.R_SHOULDER], -up) == pytest.approx(deg)
    assert j[sk.L_WRIST, 2] > 0 and j[sk.R_ELBOW, 2] > 0
    j = joints(body, Posture(shoulder_abduction_deg=(deg, deg)))
    assert _angle_deg(j[sk.L_ELBOW] - j[sk.L_SHOULDER], -up) == pytest.approx(deg)
    assert j[sk.L_ELBOW, 0] > j[sk.L_SHOULDER, 0] and j[sk.R_ELBOW, 0] < j[sk.R_SHOULDER, 0]
    j = joints(body, Posture(hip_flexion_deg=(deg, 0.0), knee_flexion_deg=(deg + 20, 0.0)))
    assert _angle_deg(j[sk.L_KNEE] - j[sk.L_HIP], j[sk.L_ANKLE] - j[sk.L_KNEE]) == pytest.approx(deg + 20)
    j = joints(body, Posture(neck_flexion_deg=deg))
    assert _angle_deg(j[sk.HEAD] - j[sk.THORAX], up) > 5.0 and j[sk.HEAD, 2] > 0


def test_sides_heading_and_lateral_bend_follow_the_documented_conventions():
    body = Body.from_height(1.75)
    j = joints(body, Posture())
    assert j[sk.L_SHOULDER, 0] > 0 > j[sk.R_SHOULDER, 0]       # facing +z, the left side is +x
    assert j[sk.NECK, 2] > 0                                     # the nose is in front
    j = joints(body, Posture(), pelvis_xz_m=(1.0, 2.0), heading_rad=np.pi / 2)
    assert j[sk.HIP, [0, 2]] == pytest.approx([1.0, 2.0])
    assert j[sk.NECK, 0] > 1.0                                   # faces +x
    assert facing(np.pi / 2) == pytest.approx([1, 0, 0])
    assert heading_towards((0, 0), (-1, 0)) == pytest.approx(-np.pi / 2)
    assert joints(body, Posture(trunk_lateral_deg=20))[sk.THORAX, 0] < 0     # toward the right
    assert joints(body, Posture(trunk_twist_deg=30))[sk.R_SHOULDER, 2] > 0   # chest turns left
    assert joints(body, Posture(neck_yaw_deg=40))[sk.NECK, 0] > 0            # looks left


def test_on_floor_puts_the_lower_ankle_on_the_floor_in_a_squat():
    body = Body.from_height(1.72)
    squat = Posture(trunk_flexion_deg=40, hip_flexion_deg=(110, 110), knee_flexion_deg=(120, 120))
    j = joints(body, squat)
    assert j[[sk.L_ANKLE, sk.R_ANKLE], 1].min() - FLOOR == pytest.approx(body.ankle_height_m)
    assert j[sk.HIP, 1] - FLOOR < 0.7 * body.hip_height_m           # the pelvis came down
    lifted = joints(body, Posture(hip_flexion_deg=(60, 0), knee_flexion_deg=(60, 0)))
    assert lifted[sk.R_ANKLE, 1] - FLOOR == pytest.approx(body.ankle_height_m)
    assert lifted[sk.L_ANKLE, 1] > lifted[sk.R_ANKLE, 1] + 0.1
    floating = joints(body, squat, on_floor=False)
    assert floating[sk.HIP, 1] - FLOOR == pytest.approx(body.hip_height_m)


def test_out_of_range_postures_are_clamped_or_refused():
    body = Body.from_height(1.72)
    bad = Posture(elbow_flexion_deg=(-20.0, 170.0), trunk_flexion_deg=120.0)
    assert len(bad.violations()) == 3
    assert np.allclose(joints(body, bad), joints(body, bad.clamped()))
    assert not bad.clamped().violations()
    with pytest.raises(PostureError, match="elbow_flexion_deg.left"):
        joints(body, bad, strict=True)
    with pytest.raises(PostureError, match="neck_yaw_deg"):
        joints(body, Posture(neck_yaw_deg=float("nan")))
    with pytest.raises(ValueError, match="height_m"):
        Body.from_height(0.4)
    with pytest.raises(ValueError, match="sex"):
        Body.from_height(1.7, "X")


def test_sequences_match_frame_by_frame_calls():
    body = Body.from_height(1.6, "F")
    rng = np.random.default_rng(1)
    postures = [Posture.from_vector(v) for v in _random_angles(rng, 5)]
    xz, hd = rng.normal(size=(5, 2)), rng.normal(size=5)
    seq = joints_seq(body, postures, xz, hd)
    for t, p in enumerate(postures):
        assert np.allclose(seq[t], joints(body, p, xz[t], hd[t]))
        assert np.allclose(Posture.from_vector(p.to_vector()).to_vector(), p.to_vector())
    assert joints_seq(body, [], (0, 0)).shape == (0, 17, 3)
