"""Physically motivated simulated wrist accelerometer (dissertation chapter 2).

The dissertation recorded the right-wrist accelerometer of 20 drivers in a
driving simulator (Xsens MVN, 3 axes, m/s^2, 100 Hz) while they drove and
performed five manual distractions on cue (Phone, Texting, TouchScreen, Drink,
Marker), plus non-coupled hand motions labelled "Other" (scratching the face,
touching an arm, ...). Those data are private; this module generates data with
the same physical structure. Nothing here is "noise around templates": every
sample is the specific force at a point on a moving forearm, expressed in a
sensor frame that turns with the forearm.

Frames and units
----------------
* Vehicle frame ("world" below): X forward, Y left, Z up; metres; origin at
  the driver's right shoulder joint when sitting upright. Gravity
  g_world = (0, 0, -9.81) m/s^2.
* Sensor frame (strapped on the back of the right wrist):
  x = along the forearm, elbow -> hand; y = radial axis (towards the thumb);
  z = x cross y, out of the back of the wrist. With the hand on the rim at
  2-4 o'clock and the elbow out to the side, the forearm crosses the
  steering-wheel axis at a large angle, so x is roughly perpendicular to it
  (the dissertation's Figure 2.1); the forearm is near horizontal, x reads
  about 0-4 m/s^2 and gravity lies mostly on y/z. Lifting or lowering the
  forearm (reaching down to the console, up to the mouth or ear) moves
  gravity onto x -- the dissertation's "projection of gravity on the x-axis
  substantially changes" -- while pronation/supination (turning the phone,
  tilting the cup) moves it between y and z only. Marker, which needs no
  forearm twist, is therefore quiet on y and z, as the dissertation notes.
* Accelerometer reading = specific force in the sensor frame,

      a_meas = clip(M^T R^T (a_sensor + a_vehicle + vib - g_world) (1 + scale) + bias + noise),

  R = [x y z] (world <- sensor); M a mounting misalignment (per subject:
  roll about the forearm N(0, 12 deg) -- a strap sits rotated --, pitch/yaw
  N(0, 3 deg); per trial +-4/1/1 deg more); a_sensor the second derivative of
  the sensor position (wrist + 3 cm along z, so forearm rotation adds
  centripetal and tangential terms); a_vehicle the car's longitudinal and
  lateral acceleration; vib road vibration; scale error N(0, 1 %); bias
  N(0, 0.1) m/s^2 per axis per subject (+ N(0, 0.03) per trial); white noise
  0.02-0.04 m/s^2 rms; clipped to +-16 g (+-156.9 m/s^2) and quantised to
  16 bits (LSB 0.0048 m/s^2); float32.

Kinematic chain
---------------
Shoulder -> elbow -> wrist with segment lengths from body height H:
upper arm 0.186 H, forearm 0.146 H, hand 0.108 H. Body landmarks (ear,
mouth, chest, knee, ...) and the car interior (wheel centre 0.44 m ahead and
0.24 m below the shoulder, console, cup holder, touch screen low on the centre
stack, passenger seat, mirror, gear lever) are wrist positions in shoulder
coordinates for a 1.75 m driver, scaled by H / 1.75 (the seat is adjusted to
the body) plus a per-subject seat offset. The wheel (radius 0.19 m) leans
25 deg from vertical. A hand path prescribes the wrist position W(t); the
elbow E follows from two-link inverse kinematics with an elbow swivel angle
phi about the shoulder-wrist line (0 = elbow hanging lowest, positive = out
to the right). Targets beyond 0.95 of the arm length are reached by leaning
the trunk (the shoulder S moves towards the target). The forearm roll psi
(pronation/supination) turns the thumb axis about u = (W - E)/|W - E|:

      y = cos(psi) n + sin(psi) (u x n),   n = unit(u x (E - S))   (arm-plane normal)

Each activity is a reach -> act -> return sequence of via-points (wrist
position, desired thumb direction, elbow swivel, movement time, dwell).
Between via-points the wrist position, psi and phi follow minimum-jerk
profiles s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5, superposed (Flash & Hogan)
so that a movement may start before the previous one ends. Every activity
may start with a quick detach (3-7 cm pull back along the forearm and 1-3 cm
up in 0.18-0.3 s; per-subject probability 0.5-1). The act phase adds
micro-motion: thumb taps while texting (2-4 Hz, 1-2 mm, in bursts), pokes
(1-2 cm) and swipes (4-8 cm) on the screen, a 15-35 deg cup tilt and 1-3 cm
lift while sipping, scratching (3-5 Hz, 5-10 mm), rubbing (1.5-3 Hz,
1.5-3.5 cm), sway while holding (0.1-1 Hz, ~1 cm), a 5-9 cm gear stroke.

Activities (times for movement-time factor 1; subject, style and road scale them):

* Phone: wheel -> phone spot (console / cup holder / lap) -> [look at it in
  front of the chest to dial, 0.5-1.8 s, like Texting] -> ear (or held on
  speaker in front of the mouth) for 1.5-4 s -> phone spot -> wheel.
* Texting: wheel -> phone spot -> in front of the chest or low at the side,
  palm up, typing 2-5.5 s -> phone spot -> wheel. Same onset as Phone.
* TouchScreen: wheel -> centre stack, pronated, 1.5-4.5 s of taps/swipes ->
  wheel. A slow wrist motion below the chest, like Texting and Marker.
* Drink: wheel -> cup holder -> [pause 1-3 s holding the cup to check the
  road, at the chest or just above the holder: "drinking with a break";
  per-subject probability, x1.5 on city roads] -> mouth, sip 1-2.5 s ->
  cup holder -> wheel.
* Marker: wheel -> passenger seat (trunk lean) -> cup holder -> wheel; short,
  with little forearm rotation.
* Other (non-coupled): scratch face / head, touch or rub the left arm, hand
  to the right knee, shift gear, adjust the mirror. Hand-to-knee and
  shift-gear are short, low-rotation reaches like Marker. Three more hold the
  hand where a distraction does: wipe the mouth (straight from the wheel,
  no cup), scratch the ear (no phone picked up first), turn a vent knob on
  the centre stack (a knob, no taps), grab something from the passenger seat
  (straight back, no cup holder) and rest the hand in the lap, so posture
  alone does not separate Other from the distractions.

Personal style: per subject, body-landmark offsets N(0, 3 cm), thumb directions
perturbed (sd 0.25), swivel offsets N(0, 8 deg), dwell-time factors per
activity (log-normal sd 0.25) and movement-time factors (sd 0.12); per
repetition jitter on top (positions 2-4 cm, thumb 0.2-0.3, swivel 6 deg,
times 15 %).

Driving
-------
City and highway blocks of 2-5 min. Steering-wheel angle = lane keeping
(band-limited 0.05-0.6 Hz, 1.5 deg rms highway, 2.5 deg city) + highway curves
(3-15 deg, 3-20 s) and lane changes (2-5 deg doublets) + city turns at
intersections (90-200 deg). The right hand follows the rim:
grip angle = clock0 - lim tanh(delta / lim) with lim 15-30 deg per subject
(push-pull steering: the hand slides on the rim) or 75-120 deg in a turn
steered hand over hand (per-subject probability 0.03-0.2): such turns lift
the forearm and can trigger the detector, as sharp turns did in the
dissertation. Vehicle: highway 27-31 m/s, city 10-15 m/s; stops at lights
(braking 1.8-3.5 m/s^2, 6 % hard 5.5-8), turns slowed to 4-7 m/s; speed
changes between road types at 0.8-1.5 m/s^2; lateral acceleration
v^2 tan(delta / 16) / 2.7 (steering ratio 16, wheelbase 2.7 m); city bumps
(decaying 6-12 Hz, 1-4 m/s^2). The dissertation's simulator had a fixed base
(no vehicle acceleration); it is kept here because the product drives real
cars. Road vibration: 2-25 Hz noise, rms 0.12 + 0.010 v m/s^2 (v in m/s;
x/y/z weights 0.5/0.4/1), halved with the hand off the wheel.

Subjects
--------
Like the dissertation's cohort: 25-55 y (mean 38.8, SD 10.2), BMI 26.9 +- 5.8
(right-skewed), 8 F / 12 M for n = 20. Height from sex (F 1.63 +- 0.065 m,
M 1.77 +- 0.07 m). Speed: a movement-time factor (log-normal sd 0.18, +0.4 %
per year over 38); city roads slow a subject down by a further 5-40 %.
BMI -> range of motion: rom = clip(1 - 0.015 (BMI - 25), 0.7, 1.05) scales the
forearm rotation and swivel excursions away from the wheel posture, and the
elbow is held further out (+0.8 deg per BMI unit over 27). Strategies: drink
pause probability (30 % of drivers 0.4-0.8, others 0-0.15), phone spot,
ear vs speaker, look-before-call probability, texting position
(front / side / mixed), wheel grip clock angle (55-125 deg), detach
probability, rate of Other motions (1.2-4.2 per 15 min, x1.6 in baseline).

Trials
------
"baseline": regular driving with Other motions only. "exp1".."exp5": the
five distractions in random order, each five times, one cue about every 30 s
(27-33 s apart; the hand leaves the wheel 0.8-2.5 s after the cue; a cue
that comes while the hand is still busy waits), plus Other motions: most on
their own (at least 9 s before and 20 s after a distraction's cue), and, per
distraction with probability ``OTHER_NEXT_TO_DISTRACTION_PROB`` each, one
right before it (the distraction then starts 1-3 s after the hand is back)
and one right after it (0.5-2.5 s after the hand is back). "drive" (:func:`simulate_drive`): the same with
the distractions in random order for as long as the drive lasts.
Events: start_s = the hand leaves the wheel, end_s = the hand is back.
Seeds: every trial draws from SeedSequence([seed, subject_id, trial]), so a
(seed, subject, trial) triple always gives the identical array.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Iterator

import numpy as np

from edge_runtime.wearable.labels import CLASSES, DISTRACTIONS, OTHER

SAMPLE_RATE_HZ = 100
G = 9.81
"""Standard gravity used by the simulator (m/s^2)."""
RANGE_MPS2 = 16 * 9.80665
"""Accelerometer full scale: +-16 g = +-156.9 m/s^2."""
LSB_MPS2 = RANGE_MPS2 / 32768
"""16-bit quantisation step (m/s^2)."""

UPPER_ARM_PER_H = 0.186
FOREARM_PER_H = 0.146
HAND_PER_H = 0.108
WHEEL_RADIUS_M = 0.19
WHEEL_TILT_DEG = 25.0
"""The wheel plane leans this far from vertical (top away from the driver)."""
STEER_RATIO = 16.0
WHEELBASE_M = 2.7
SENSOR_OFFSET_M = 0.03
"""Sensor centre above the forearm axis, along the sensor z axis (back of the wrist)."""

TRIALS = ("baseline", "exp1", "exp2", "exp3", "exp4", "exp5")
OTHER_KINDS = ("scratch_face", "scratch_head", "touch_arm", "hand_to_knee", "shift_gear", "adjust_mirror",
               "wipe_mouth", "scratch_ear", "adjust_vent", "grab_from_seat", "hand_to_lap")
OTHER_KIND_PROB = (0.1, 0.05, 0.07, 0.1, 0.1, 0.05, 0.11, 0.11, 0.1, 0.1, 0.11)
"""How often each Other kind is drawn. The last five hold the hand where a distraction does (mouth as
in Drink, ear as in Phone, centre stack as in TouchScreen, passenger seat as in Marker, lap as a phone
spot), so a posture alone does not tell Other from a distraction; the path there and the micro-motion do."""
OTHER_NEXT_TO_DISTRACTION_PROB = 0.1
"""Per distraction, the chance of an Other motion right before it, and (independently) right after it."""


# ----------------------------------------------------------------------------------------------
# public data types

@dataclass
class Event:
    """A ground-truth hand activity: hand leaves the wheel at start_s, is back at end_s."""

    start_s: float
    end_s: float
    label: str
    detail: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        d = {"start_s": round(float(self.start_s), 3), "end_s": round(float(self.end_s), 3), "label": self.label}
        d.update({k: v for k, v in self.detail.items() if k not in d})
        return d

    @classmethod
    def from_json(cls, d: dict) -> "Event":
        detail = {k: v for k, v in d.items() if k not in ("start_s", "end_s", "label")}
        return cls(float(d["start_s"]), float(d["end_s"]), str(d["label"]), detail)


@dataclass
class Subject:
    """One simulated driver. Lengths in m, angles in degrees, rates per 15 min."""

    subject_id: int
    sex: str
    age: int
    height_m: float
    bmi: float
    speed: float
    """Movement-time factor (> 1 = slower)."""
    rom: float
    """Range-of-motion factor from BMI (forearm rotation and swivel excursions)."""
    grip_clock_deg: float
    """Right-hand grip position on the rim, degrees clockwise from 12 o'clock (90 = 3 o'clock)."""
    grip_follow_deg: float
    """How far the right hand turns with the wheel before sliding on the rim."""
    hand_over_hand_prob: float
    """Probability that a city turn is steered hand over hand (right hand follows the wheel far)."""
    swivel_deg: float
    """Resting elbow swivel (elbow out to the side) with the hand on the wheel."""
    drink_pause_prob: float
    """Probability of drinking with a break (hold the cup and check the road)."""
    phone_spot: str
    """Where the phone lies: console, cupholder or lap."""
    phone_hold: str
    """ear or speaker (held in front of the mouth)."""
    phone_look_prob: float
    """Probability of looking at the phone (dialling) in front of the chest before lifting it to the ear."""
    texting_pos: str
    """front, side or mixed."""
    city_slowdown: float
    """Extra movement-time factor on city roads."""
    other_rate: float
    """Other (non-coupled) hand motions per 15 minutes of driving."""
    tap_hz: float
    """Thumb tapping rate while texting."""
    style_seed: int = 0
    """Seeds the driver's personal style: where exactly they hold things, how long they dwell."""
    detach_prob: float = 0.8
    """Probability of letting go of the rim with a quick pull (else the hand slides off gently)."""
    seat_offset_m: tuple = (0.0, 0.0, 0.0)
    """Seat position offset from the nominal (m, vehicle frame)."""
    mount_rpy_deg: tuple = (0.0, 0.0, 0.0)
    """Sensor mounting misalignment (roll, pitch, yaw about x, y, z)."""
    bias_mps2: tuple = (0.0, 0.0, 0.0)
    noise_mps2: float = 0.03
    scale_err: float = 0.0

    @property
    def upper_arm_m(self) -> float:
        return UPPER_ARM_PER_H * self.height_m

    @property
    def forearm_m(self) -> float:
        return FOREARM_PER_H * self.height_m

    @property
    def hand_m(self) -> float:
        return HAND_PER_H * self.height_m

    def to_json(self) -> dict:
        d = asdict(self)
        for k, v in d.items():
            if isinstance(v, tuple):
                d[k] = [round(float(x), 4) for x in v]
            elif isinstance(v, float):
                d[k] = round(v, 4)
        return d

    @classmethod
    def from_json(cls, d: dict) -> "Subject":
        kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()
              if k in cls.__dataclass_fields__}
        return cls(**kw)


@dataclass
class Recording:
    """A simulated wrist recording: (n, 3) float32 m/s^2 at 100 Hz plus its truth."""

    acc_mps2: np.ndarray
    events: list
    subject_id: int
    trial: str
    sample_rate_hz: int = SAMPLE_RATE_HZ
    subject: Subject | None = None
    manoeuvres: list = field(default_factory=list)
    """Driving manoeuvres (not truth events): dicts with start_s, end_s, kind and parameters."""

    @property
    def t_s(self) -> np.ndarray:
        return np.arange(len(self.acc_mps2)) / float(self.sample_rate_hz)

    @property
    def duration_s(self) -> float:
        return len(self.acc_mps2) / float(self.sample_rate_hz)

    def truth_json(self) -> dict:
        return {
            "sample_rate_hz": int(self.sample_rate_hz),
            "subject_id": int(self.subject_id),
            "trial": self.trial,
            "subject": self.subject.to_json() if self.subject is not None else {"subject_id": int(self.subject_id)},
            "events": [e.to_json() for e in self.events],
            "manoeuvres": self.manoeuvres,
        }


# ----------------------------------------------------------------------------------------------
# cohort

def make_subjects(n: int = 20, seed: int = 0) -> list[Subject]:
    """A cohort like the dissertation's: 25-55 y, BMI 26.9 +- 5.8, 40 % female (8 F / 12 M for 20)."""
    if n < 1:
        raise ValueError("n must be at least 1")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5EB1]))
    n_f = int(round(0.4 * n))
    sexes = np.array(["F"] * n_f + ["M"] * (n - n_f))
    rng.shuffle(sexes)
    ages = np.clip(np.round(rng.normal(38.8, 10.2, n)), 25, 55).astype(int)
    # BMI: right-skewed (log-normal), standardised to the reported mean and SD; redraw if implausible
    for _ in range(1000):
        z = np.exp(rng.normal(0.0, 0.22, n))
        if n >= 3:
            z = (z - z.mean()) / z.std(ddof=1)
        else:
            z = (z - 1.0) / 0.22
        bmi = 26.9 + 5.8 * z
        if bmi.min() >= 18.0 and bmi.max() <= 45.0:
            break
    bmi = np.clip(bmi, 18.0, 45.0)
    subjects = []
    for i in range(n):
        r = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5EB2, i]))
        sex = str(sexes[i])
        h = r.normal(1.63, 0.065) if sex == "F" else r.normal(1.77, 0.07)
        h = float(np.clip(h, 1.48, 1.98))
        age = int(ages[i])
        speed = float(np.exp(r.normal(0.0, 0.18)) * (1.0 + 0.004 * (age - 38)))
        rom = float(np.clip(1.0 - 0.015 * (bmi[i] - 25.0), 0.7, 1.05))
        strat = r.random()
        subjects.append(Subject(
            subject_id=i + 1,
            sex=sex,
            age=age,
            height_m=round(h, 3),
            bmi=round(float(bmi[i]), 1),
            speed=round(speed, 3),
            rom=round(rom, 3),
            grip_clock_deg=round(float(r.uniform(55, 125)), 1),
            grip_follow_deg=round(float(r.uniform(15, 30)), 1),
            hand_over_hand_prob=round(float(r.uniform(0.03, 0.2)), 3),
            swivel_deg=round(float(r.uniform(8, 30) + 0.8 * max(0.0, bmi[i] - 27)), 1),
            drink_pause_prob=round(float(r.uniform(0.4, 0.8) if strat < 0.3 else r.uniform(0.0, 0.15)), 3),
            phone_spot=str(r.choice(["console", "cupholder", "lap"], p=[0.5, 0.3, 0.2])),
            phone_hold=str(r.choice(["ear", "speaker"], p=[0.75, 0.25])),
            phone_look_prob=round(float(r.uniform(0.2, 0.9)), 3),
            texting_pos=str(r.choice(["front", "side", "mixed"], p=[0.6, 0.25, 0.15])),
            city_slowdown=round(float(r.uniform(1.05, 1.4)), 3),
            other_rate=round(float(r.uniform(1.2, 4.2)), 2),
            tap_hz=round(float(r.uniform(2.0, 4.0)), 2),
            style_seed=int(r.integers(0, 2**31 - 1)),
            detach_prob=round(float(np.clip(r.uniform(0.5, 1.0) - 0.01 * max(0.0, bmi[i] - 30), 0.2, 1.0)), 3),
            seat_offset_m=tuple(float(v) for v in np.round(r.normal(0, [0.03, 0.015, 0.02]), 4)),
            mount_rpy_deg=tuple(float(v) for v in np.round(r.normal(0, [12.0, 3.0, 3.0]), 2)),
            bias_mps2=tuple(float(v) for v in np.round(r.normal(0, 0.1, 3), 4)),
            noise_mps2=round(float(r.uniform(0.02, 0.04)), 4),
            scale_err=round(float(r.normal(0, 0.01)), 4),
        ))
    return subjects


# ----------------------------------------------------------------------------------------------
# small maths

def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def _minjerk(tau: np.ndarray) -> np.ndarray:
    tau = np.clip(tau, 0.0, 1.0)
    return tau ** 3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def _rot_rpy(rpy_deg) -> np.ndarray:
    r, p, y = np.radians(rpy_deg)
    cx, sx, cy, sy, cz, sz = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _band_noise(rng: np.random.Generator, n: int, f_lo: float, f_hi: float, fs: float = SAMPLE_RATE_HZ,
                dims: int = 1) -> np.ndarray:
    """Unit-rms band-limited Gaussian noise (n, dims), shaped in the frequency domain."""
    if n < 4:
        return np.zeros((n, dims))
    w = rng.standard_normal((n, dims))
    spec = np.fft.rfft(w, axis=0)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    # smooth band-pass (4th-order-like roll-offs)
    h = 1.0 / (1.0 + (f_lo / np.maximum(f, 1e-6)) ** 4) / (1.0 + (f / f_hi) ** 4)
    out = np.fft.irfft(spec * h[:, None], n=n, axis=0)
    sd = out.std(axis=0, keepdims=True)
    return out / np.maximum(sd, 1e-12)


def _smooth(x: np.ndarray, win: int) -> np.ndarray:
    """Centred moving average with edge padding (keeps step-like parameters continuous)."""
    if win <= 1:
        return np.asarray(x, float)
    k = np.ones(win) / win
    xp = np.pad(np.asarray(x, float), (win // 2, win - 1 - win // 2), mode="edge")
    return np.convolve(xp, k, mode="valid")


def _tukey(m: int, frac: float = 0.3) -> np.ndarray:
    if m <= 1:
        return np.ones(max(m, 0))
    x = np.linspace(0, 1, m)
    w = np.ones(m)
    a = frac / 2
    if a > 0:
        lo, hi = x < a, x > 1 - a
        w[lo] = 0.5 * (1 - np.cos(np.pi * x[lo] / a))
        w[hi] = 0.5 * (1 - np.cos(np.pi * (1 - x[hi]) / a))
    return w


# ----------------------------------------------------------------------------------------------
# body and car geometry (shoulder frame for a 1.75 m driver; scaled by H / 1.75)

_LANDMARKS = {
    # wrist positions (m) when the hand is at ...
    "ear": (0.10, 0.06, 0.00),
    "speaker": (0.26, 0.10, -0.08),
    "mouth": (0.14, 0.12, 0.05),
    "chest_pause": (0.28, 0.03, -0.14),
    "text_front": (0.30, 0.12, -0.20),
    "text_side": (0.26, -0.06, -0.27),
    "console": (0.40, -0.14, -0.36),
    "cupholder": (0.28, -0.17, -0.40),
    "lap": (0.24, 0.08, -0.45),
    "screen": (0.43, -0.24, -0.31),
    "passenger_seat": (0.22, -0.46, -0.42),
    "knee": (0.36, 0.05, -0.46),
    "gear": (0.37, -0.19, -0.35),
    "cheek": (0.10, 0.13, 0.07),
    "head": (0.03, 0.12, 0.22),
    "left_arm": (0.12, 0.30, -0.10),
    "mirror": (0.44, -0.14, 0.14),
    "wheel_centre": (0.44, 0.19, -0.24),
}

# desired thumb (sensor y) directions in the vehicle frame at the via-points
_THUMB = {
    "grasp_down": (0.3, 1.0, 0.2),      # palm down picking something up, thumb medial
    "ear": (-1.0, 0.1, 0.2),            # palm to the head, thumb backwards
    "speaker": (0.0, -0.8, 0.6),
    "text": (0.0, -1.0, 0.35),          # palm up towards the face, thumb lateral
    "cup_up": (0.25, 0.1, 1.0),         # thumb up holding a cup
    "mouth": (-0.75, 0.2, 0.6),         # cup tilted towards the face
    "screen": (0.1, 1.0, 0.35),          # index pointing, forearm pronated
    "marker": (0.5, 0.35, 0.8),         # little rotation
    "knee": (0.35, 0.55, 0.75),
    "gear": (0.4, 0.3, 0.85),
    "cheek": (-0.4, 0.0, 1.0),
    "head": (-0.6, 0.3, 0.6),
    "left_arm": (0.2, 0.0, 1.0),
    "mirror": (0.2, 0.5, 0.8),
}

_SWIVEL = {  # elbow swivel (deg) at the via-points, before the subject's BMI offset
    "ear": 40, "speaker": 25, "mouth": 35, "chest_pause": 20, "text": 15, "console": 25,
    "cupholder": 30, "lap": 10, "screen": 20, "passenger_seat": 45, "knee": 10, "gear": 25,
    "cheek": 35, "head": 60, "left_arm": 5, "mirror": 40,
}


class _Body:
    """Per-subject geometry: segment lengths, landmarks, wheel."""

    def __init__(self, s: Subject):
        k = s.height_m / 1.75
        self.lu, self.lf = s.upper_arm_m, s.forearm_m
        self.reach = 0.95 * (self.lu + self.lf)
        off = np.asarray(s.seat_offset_m, float)
        self.lm = {name: np.asarray(v, float) * k for name, v in _LANDMARKS.items()}
        for name in ("console", "cupholder", "screen", "passenger_seat", "gear", "mirror", "wheel_centre"):
            self.lm[name] = self.lm[name] + off  # car-fixed points move with the seat offset
        b = math.radians(WHEEL_TILT_DEG)
        self.wheel_c = self.lm["wheel_centre"]
        self.wheel_up = np.array([math.sin(b), 0.0, math.cos(b)])   # 12 o'clock direction
        self.wheel_right = np.array([0.0, -1.0, 0.0])               # 3 o'clock direction
        self.wheel_axis = np.array([-math.cos(b), 0.0, math.sin(b)])  # towards the driver
        self.rom = s.rom
        self.swivel_extra = 0.8 * max(0.0, s.bmi - 27.0)
        # personal style: each driver holds things a little differently, every time the same way
        st = np.random.default_rng(np.random.SeedSequence([int(s.style_seed), 0x57E]))
        body_pts = ("ear", "speaker", "mouth", "chest_pause", "text_front", "text_side", "lap", "knee", "cheek",
                    "head", "left_arm")
        for name in body_pts:
            self.lm[name] = self.lm[name] + st.normal(0, 0.03, 3)
        self.thumb = {name: _unit(np.asarray(v, float) + st.normal(0, 0.25, 3)) for name, v in _THUMB.items()}
        self.swivel = {name: float(v + st.normal(0, 8.0)) for name, v in _SWIVEL.items()}
        self.dwell = {name: float(np.exp(st.normal(0, 0.25))) for name in DISTRACTIONS + OTHER_KINDS}
        self.move = {name: float(np.exp(st.normal(0, 0.12))) for name in DISTRACTIONS + OTHER_KINDS}

    def wheel_pose(self, grip_deg: np.ndarray):
        """Wrist position and thumb direction for the hand at grip angle (deg clockwise from 12)."""
        g = np.radians(np.asarray(grip_deg, float))[:, None]
        radial = np.cos(g) * self.wheel_up + np.sin(g) * self.wheel_right
        tangent = np.sin(g) * self.wheel_up - np.cos(g) * self.wheel_right  # towards 12 o'clock
        grip = self.wheel_c + WHEEL_RADIUS_M * radial
        wrist = grip + 0.06 * self.wheel_axis + 0.03 * radial + np.array([0.0, 0.0, -0.02])
        return wrist, tangent

    def frames(self, wrist: np.ndarray, swivel_deg: np.ndarray):
        """Two-link IK: elbow, forearm axis u and arm-plane normal n for (m, 3) wrist positions."""
        w = np.atleast_2d(wrist)
        d = np.linalg.norm(w, axis=1, keepdims=True)
        lean = np.maximum(d - self.reach, 0.0)           # trunk lean: the shoulder follows the target
        wh = w / np.maximum(d, 1e-9)
        shoulder = lean * wh
        dd = np.minimum(d, self.reach)
        c = (dd ** 2 + self.lu ** 2 - self.lf ** 2) / (2 * dd)
        rho = np.sqrt(np.maximum(self.lu ** 2 - c ** 2, 1e-9))
        ref = np.array([-0.45, 0.0, -0.9])               # elbow hangs down and back
        e1 = _unit(ref - (wh @ ref)[:, None] * wh)
        e2 = np.cross(wh, e1)
        phi = np.radians(np.asarray(swivel_deg, float)).reshape(-1, 1)
        elbow = shoulder + c * wh + rho * (np.cos(phi) * e1 - np.sin(phi) * e2)
        u = _unit(w - elbow)
        n = _unit(np.cross(u, elbow - shoulder))
        return elbow, u, n

    def psi_from_thumb(self, wrist, swivel_deg, thumb) -> np.ndarray:
        _, u, n = self.frames(wrist, swivel_deg)
        b = np.cross(u, n)
        th = np.atleast_2d(thumb)
        return np.arctan2(np.sum(th * b, axis=1), np.sum(th * n, axis=1))


# ----------------------------------------------------------------------------------------------
# activities as via-point plans

@dataclass
class _Via:
    pos: np.ndarray | None  # wrist target (m); None = back on the wheel
    thumb: np.ndarray | None
    swivel: float
    move_s: float
    dwell_s: float = 0.0
    act: str | None = None
    overlap: float = 0.0  # fraction of this movement overlapping the previous one (if no dwell)
    keep_roll_sd: float | None = None  # no pronation/supination: roll stays at the wheel's (+ N(0, sd) rad)


def _jit(rng, v, sd):
    return np.asarray(v, float) + rng.normal(0, sd, np.shape(v))


def _plan(kind: str, body: _Body, subj: Subject, rng: np.random.Generator, slow: float, city: bool,
          detail: dict) -> list[_Via]:
    """Via-points of one activity (without the starting wheel pose); fills ``detail`` (strategy)."""
    lm = body.lm
    sw = body.swivel_extra

    def P(name, sd=0.025):
        return _jit(rng, lm[name], sd)

    def T(name, sd=0.2):
        return _unit(_jit(rng, body.thumb[name], sd))

    def S(name, sd=6.0):
        return float(body.swivel[name] + sw + rng.normal(0, sd))

    def mv(base, sd=0.15):  # movement time (s)
        return float(base * slow * body.move[kind] * np.exp(rng.normal(0, sd)))

    def dw(lo, hi):
        return float(rng.uniform(lo, hi) * slow * body.dwell[kind])

    back = _Via(None, None, subj.swivel_deg, mv(0.9))
    if kind in ("Phone", "Texting"):
        spot = subj.phone_spot
        v = [_Via(P(spot), T("grasp_down"), S(spot), mv(0.85), dw(0.25, 0.6), "grasp")]
        if kind == "Phone":
            detail["look_first"] = bool(rng.random() < subj.phone_look_prob)
            detail.update(hold=subj.phone_hold, spot=spot)
            if detail["look_first"]:  # look at the screen to dial/answer: like Texting
                v.append(_Via(P("text_front", 0.04), T("text", 0.3), S("text"), mv(0.8), dw(0.5, 1.8), "taps"))
            tgt = "ear" if subj.phone_hold == "ear" else "speaker"
            v.append(_Via(P(tgt), T(tgt), S(tgt), mv(0.9), dw(1.5, 4.0), "sway"))
        else:
            pos = subj.texting_pos
            if pos == "mixed":
                pos = "front" if rng.random() < 0.5 else "side"
            tgt = "text_front" if pos == "front" else "text_side"
            detail.update(position=pos, spot=spot)
            v.append(_Via(P(tgt, 0.035), T("text", 0.3), S("text"), mv(0.9), dw(2.0, 5.5), "taps"))
        v.append(_Via(P(spot), T("grasp_down"), S(spot), mv(0.9), dw(0.2, 0.5), "grasp"))
        v.append(back)
    elif kind == "TouchScreen":
        v = [_Via(P("screen", 0.03), T("screen", 0.3), S("screen"), mv(1.0), dw(1.5, 4.5), "screen"), back]
    elif kind == "Drink":
        v = [_Via(P("cupholder"), T("cup_up"), S("cupholder"), mv(0.85), dw(0.3, 0.6), "grasp")]
        p_pause = min(1.0, subj.drink_pause_prob * (1.5 if city else 1.0))
        detail["strategy"] = "consecutive"
        if rng.random() < p_pause:
            where = "chest_pause" if rng.random() < 0.75 else "cupholder"
            detail.update(strategy="pause", pause_at=where)
            pos = P("chest_pause") if where == "chest_pause" else P("cupholder") + np.array([0.04, 0.0, 0.06])
            v.append(_Via(pos, T("cup_up"), S("chest_pause"), mv(0.7), dw(1.0, 3.0), "sway"))
        v.append(_Via(P("mouth", 0.02), T("mouth", 0.2), S("mouth"), mv(0.9), dw(1.0, 2.5), "sip"))
        v.append(_Via(P("cupholder"), T("cup_up"), S("cupholder"), mv(0.9), dw(0.2, 0.5), "grasp"))
        v.append(back)
    elif kind == "Marker":
        v = [_Via(P("passenger_seat", 0.04), T("marker", 0.2), S("passenger_seat"), mv(0.9), dw(0.2, 0.5), "grasp",
                  keep_roll_sd=0.15),
             _Via(P("cupholder"), T("marker", 0.2), S("cupholder"), mv(0.7), dw(0.15, 0.4), "grasp",
                  keep_roll_sd=0.15),
             back]
    elif kind == "scratch_face":
        v = [_Via(P("cheek"), T("cheek", 0.3), S("cheek"), mv(0.75), dw(0.8, 2.5), "scratch"), back]
    elif kind == "scratch_head":
        v = [_Via(P("head"), T("head", 0.3), S("head"), mv(0.85), dw(0.8, 2.5), "scratch"), back]
    elif kind == "touch_arm":
        v = [_Via(P("left_arm"), T("left_arm", 0.3), S("left_arm"), mv(0.8), dw(0.6, 2.0), "rub"), back]
    elif kind == "hand_to_knee":
        v = [_Via(P("knee", 0.03), T("knee", 0.2), S("knee"), mv(0.75), dw(0.5, 3.0), "sway", keep_roll_sd=0.2), back]
    elif kind == "shift_gear":
        v = [_Via(P("gear", 0.02), T("gear", 0.2), S("gear"), mv(0.7), dw(0.2, 0.4), "grasp", keep_roll_sd=0.2),
             _Via(None, None, 0.0, mv(0.35), dw(0.1, 0.3), None),  # stroke: filled in below
             back]
        stroke = v[0].pos + np.array([rng.choice([-1, 1]) * rng.uniform(0.05, 0.09), 0.0, 0.0])
        v[1] = _Via(stroke, v[0].thumb, v[0].swivel, v[1].move_s, v[1].dwell_s, keep_roll_sd=0.2)
    elif kind == "adjust_mirror":
        v = [_Via(P("mirror", 0.02), T("mirror", 0.2), S("mirror"), mv(1.0), dw(0.8, 2.0), "adjust"), back]
    elif kind == "wipe_mouth":  # straight from the wheel to the mouth: no cup holder on the way
        v = [_Via(P("mouth", 0.03), T("cheek", 0.3), S("mouth"), mv(0.8), dw(0.5, 2.0), "rub"), back]
    elif kind == "scratch_ear":  # at the ear like a call, but no phone picked up first
        v = [_Via(P("ear", 0.03), T("ear", 0.3), S("ear"), mv(0.85), dw(0.6, 2.2), "scratch"), back]
    elif kind == "adjust_vent":  # the centre stack like TouchScreen, a knob turned instead of taps
        v = [_Via(P("console", 0.03), T("screen", 0.3), S("console"), mv(0.95), dw(0.6, 2.5), "adjust"), back]
    elif kind == "grab_from_seat":  # the passenger seat like Marker, but straight back to the wheel
        v = [_Via(P("passenger_seat", 0.05), T("marker", 0.3), S("passenger_seat"), mv(0.95), dw(0.3, 1.2),
                  "grasp", keep_roll_sd=0.2), back]
    elif kind == "hand_to_lap":  # where some drivers keep the phone, but nothing is picked up
        v = [_Via(P("lap", 0.04), T("knee", 0.3), S("lap"), mv(0.8), dw(0.8, 3.0), "sway"), back]
    else:
        raise ValueError(f"unknown activity {kind!r}")
    # soften a few transitions: a movement may start before the previous one has stopped
    for a, b in zip(v[:-1], v[1:]):
        if a.dwell_s < 0.25 and rng.random() < 0.5:
            b.overlap = float(rng.uniform(0.1, 0.3))
    return v


def _micro(act: str, m: int, rng: np.random.Generator, subj: Subject, fs: float = SAMPLE_RATE_HZ):
    """Activity micro-motion during a dwell: (m, 3) wrist displacement (m) and (m,) roll (rad)."""
    t = np.arange(m) / fs
    env = _tukey(m, 0.4)[:, None]
    dpos = np.zeros((m, 3))
    dpsi = np.zeros(m)
    if m < 3 or act is None:
        return dpos, dpsi
    if act == "sway":
        dpos = 0.008 * _band_noise(rng, m, 0.1, 1.0, dims=3)
        dpsi = math.radians(3) * _band_noise(rng, m, 0.1, 1.0)[:, 0]
    elif act == "taps":
        f = subj.tap_hz * np.exp(rng.normal(0, 0.1))
        burst = (_band_noise(rng, m, 0.05, 0.5)[:, 0] > -0.3).astype(float)
        ph = 2 * np.pi * np.cumsum(f * np.exp(0.1 * _band_noise(rng, m, 0.1, 1.0)[:, 0])) / fs
        taps = np.maximum(np.sin(ph), 0) ** 2 * burst
        dpos[:, 2] = -rng.uniform(0.001, 0.002) * taps
        dpos += 0.012 * _band_noise(rng, m, 0.1, 0.8, dims=3)
        dpsi = math.radians(6) * _band_noise(rng, m, 0.1, 0.8)[:, 0]
    elif act == "screen":
        # pokes (forward) and swipes (sideways) as min-jerk strokes
        tt = 0.3
        while tt < m / fs - 0.5:
            i0 = int(tt * fs)
            if rng.random() < 0.6:
                dur = rng.uniform(0.25, 0.45)
                k = np.arange(int(dur * fs))
                prof = np.sin(np.pi * k / len(k)) ** 2
                dpos[i0:i0 + len(k), 0] += rng.uniform(0.01, 0.02) * prof[: m - i0]
            else:
                dur = rng.uniform(0.3, 0.5)
                k = np.arange(int(dur * fs))
                prof = _minjerk(2 * k / len(k)) - _minjerk(2 * k / len(k) - 1)
                sgn = rng.choice([-1, 1])
                dpos[i0:i0 + len(k), 1] += sgn * rng.uniform(0.04, 0.08) * prof[: m - i0]  # swipe and back
            tt += rng.uniform(0.5, 1.2)
        dpos += 0.005 * _band_noise(rng, m, 0.1, 1.0, dims=3)
        dpsi = math.radians(4) * _band_noise(rng, m, 0.1, 1.0)[:, 0]
    elif act == "sip":
        tilt = math.radians(rng.uniform(15, 35))
        prof = _minjerk(t / 0.5) - _minjerk((t - (m / fs - 0.5)) / 0.5)
        dpsi = -tilt * prof
        dpos[:, 2] = rng.uniform(0.01, 0.03) * prof
        dpos += 0.003 * _band_noise(rng, m, 0.2, 2.0, dims=3)
    elif act == "grasp":
        dpos[:, 2] = -rng.uniform(0.01, 0.02) * 0.5 * (1 - np.cos(2 * np.pi * t / max(t[-1], 1e-3)))
    elif act == "scratch":
        f = rng.uniform(3.0, 5.0)
        amp = rng.uniform(0.005, 0.01)
        d = _unit(rng.normal(0, 1, 3))
        dpos = amp * np.sin(2 * np.pi * f * t)[:, None] * d
        dpsi = math.radians(rng.uniform(3, 8)) * np.sin(2 * np.pi * f * t + 0.5)
    elif act == "rub":
        f = rng.uniform(1.5, 3.0)
        amp = rng.uniform(0.015, 0.035)
        dpos[:, 0] = amp * np.sin(2 * np.pi * f * t)
    elif act == "adjust":
        dpsi = math.radians(rng.uniform(5, 12)) * _band_noise(rng, m, 0.3, 1.5)[:, 0]
        dpos = 0.004 * _band_noise(rng, m, 0.3, 1.5, dims=3)
    return dpos * env, dpsi * env[:, 0]


# ----------------------------------------------------------------------------------------------
# driving: road, vehicle and steering

def _raised_cos(n_s: int) -> np.ndarray:
    k = np.arange(n_s)
    return 0.5 * (1 - np.cos(2 * np.pi * (k + 0.5) / n_s))


def _drive(rng: np.random.Generator, n: int, subj: Subject, fs: float = SAMPLE_RATE_HZ):
    """Steering angle (deg), grip follow limit (deg), vehicle accel (n, 3), speed, city mask, manoeuvres."""
    dur = n / fs
    ax = np.zeros(n)
    steer = np.zeros(n)
    lim = np.full(n, subj.grip_follow_deg)
    city = np.zeros(n, bool)
    bumps = np.zeros(n)
    man: list[dict] = []

    def pulse(t0, d, amp, arr=ax):
        i0 = int(t0 * fs)
        m = max(int(d * fs), 2)
        if i0 >= n:
            return
        p = _raised_cos(m)[: n - i0]
        arr[i0:i0 + len(p)] += amp * p

    def bump_steer(t0, amp, tin, hold, tout):
        i0 = int(t0 * fs)
        if i0 >= n:
            return
        k = np.arange(n - i0) / fs
        prof = _minjerk(k / tin) - _minjerk((k - tin - hold) / tout)
        steer[i0:] += amp * prof

    def _speed_change(t0, v_from, v_to):
        """Gentle speed change between road types (peak 0.8-1.5 m/s^2); returns its duration."""
        dv = v_to - v_from
        a_t = float(rng.uniform(0.8, 1.5))
        d = max(2.0, 2 * abs(dv) / a_t)
        pulse(t0, d, 2 * dv / d)
        return d

    # blocks
    t = 0.0
    is_city = bool(rng.random() < 0.5)
    v = float(rng.uniform(10, 15) if is_city else rng.uniform(27, 31))
    v0 = v
    while t < dur:
        blen = float(rng.uniform(120, 300))
        end = min(dur, t + blen)
        city[int(t * fs):int(end * fs)] = is_city
        if is_city:
            vc = float(rng.uniform(10, 15))
            t_tr = _speed_change(t, v, vc)
            tt = t + t_tr + float(rng.uniform(5, 20))
            while tt < end - 20:
                r = rng.random()
                if r < 0.45:  # stop at a light
                    hard = rng.random() < 0.06
                    a_b = float(rng.uniform(5.5, 8.0) if hard else rng.uniform(1.8, 3.5))
                    d_b = 2 * vc / a_b
                    pulse(tt, d_b, -a_b)
                    wait = float(rng.uniform(4, 20))
                    a_a = float(rng.uniform(1.2, 2.5))
                    pulse(tt + d_b + wait, 2 * vc / a_a, a_a)
                    man.append({"start_s": round(tt, 2), "end_s": round(tt + d_b + wait + 2 * vc / a_a, 2),
                                "kind": "hard_brake" if hard else "stop", "decel_mps2": round(a_b, 2)})
                    tt += d_b + wait + 2 * vc / a_a
                elif r < 0.8:  # turn at an intersection
                    vt = float(rng.uniform(4, 7))
                    a_b = float(rng.uniform(1.5, 3.0))
                    d_b = 2 * (vc - vt) / a_b
                    pulse(tt, d_b, -a_b)
                    amp = float(rng.choice([-1, 1]) * rng.uniform(90, 200))
                    tin, hold, tout = (float(rng.uniform(1.3, 2.5)), float(rng.uniform(0.5, 2.0)),
                                       float(rng.uniform(1.5, 2.5)))
                    ts = tt + d_b * 0.8
                    bump_steer(ts, amp, tin, hold, tout)
                    hoh = bool(rng.random() < subj.hand_over_hand_prob)
                    if hoh:
                        i0, i1 = int(ts * fs), int((ts + tin + hold + tout) * fs)
                        lim[i0:i1] = float(rng.uniform(75, 120))
                    a_a = float(rng.uniform(1.2, 2.2))
                    pulse(ts + tin + hold, 2 * (vc - vt) / a_a, a_a)
                    man.append({"start_s": round(ts, 2), "end_s": round(ts + tin + hold + tout, 2),
                                "kind": "turn_left" if amp > 0 else "turn_right", "steer_deg": round(amp, 1),
                                "hand_over_hand": hoh})
                    tt = ts + tin + hold + 2 * (vc - vt) / a_a
                # speed bumps / potholes
                if rng.random() < 0.15:
                    tb = tt + float(rng.uniform(2, 10))
                    i0 = int(tb * fs)
                    k = np.arange(min(60, max(n - i0, 0))) / fs
                    if len(k):
                        bumps[i0:i0 + len(k)] += (rng.uniform(1.0, 4.0) * np.exp(-k / 0.08)
                                                  * np.sin(2 * np.pi * rng.uniform(6, 12) * k))
                tt += float(rng.uniform(15, 50))
            # speed change into the block is implicit: v(t) integrates ax; adjust at block start
            v = vc
        else:
            vh = float(rng.uniform(27, 31))
            t_tr = _speed_change(t, v, vh)
            v = vh
            tt = t + t_tr + float(rng.uniform(5, 20))
            while tt < end - 10:
                if rng.random() < 0.7:  # curve
                    amp = float(rng.choice([-1, 1]) * rng.uniform(3, 15))
                    tin, hold, tout = float(rng.uniform(2, 5)), float(rng.uniform(3, 20)), float(rng.uniform(2, 5))
                    bump_steer(tt, amp, tin, hold, tout)
                    man.append({"start_s": round(tt, 2), "end_s": round(tt + tin + hold + tout, 2),
                                "kind": "curve", "steer_deg": round(amp, 1)})
                    tt += tin + hold + tout
                else:  # lane change: a steering doublet
                    amp = float(rng.choice([-1, 1]) * rng.uniform(2, 5))
                    d = float(rng.uniform(1.5, 2.5))
                    bump_steer(tt, amp, d / 2, 0.0, d / 2)
                    bump_steer(tt + d, -amp, d / 2, 0.0, d / 2)
                    man.append({"start_s": round(tt, 2), "end_s": round(tt + 2 * d, 2), "kind": "lane_change"})
                    tt += 2 * d
                tt += float(rng.uniform(20, 80))
        t = end
        is_city = not is_city
    # speed from the acceleration pulses (block transitions use a simple 4 s ramp)
    speed = np.maximum(v0 + np.cumsum(ax) / fs, 0.0)
    ax = np.gradient(speed) * fs  # a car standing still does not decelerate
    sd_lk = _smooth(np.where(city, 2.5, 1.5), 5 * int(fs))
    lim = _smooth(lim, int(fs))  # the hand adopts hand-over-hand steering gradually
    steer += sd_lk * _band_noise(rng, n, 0.05, 0.6)[:, 0]
    ay = speed ** 2 * np.tan(np.radians(steer / STEER_RATIO)) / WHEELBASE_M
    acc = np.stack([ax, ay, np.zeros(n)], axis=1)
    acc += np.stack([0.05 * _band_noise(rng, n, 0.05, 1.0)[:, 0], 0.05 * _band_noise(rng, n, 0.05, 1.0)[:, 0],
                     bumps], axis=1)
    return steer, lim, acc, speed, city, man


# ----------------------------------------------------------------------------------------------
# schedules

def _schedule(rng: np.random.Generator, subj: Subject, trial: str, dur_s: float) -> list[tuple[float, str, str, bool]]:
    """(start time, label, kind, follows) of every activity, in time order. ``follows``: the activity
    starts right after the one before it ends (an Other motion just after a distraction), so
    its start is only known once the one before has been simulated."""
    acts: list[tuple[float, str, str, bool]] = []
    draw_other = lambda: str(rng.choice(OTHER_KINDS, p=OTHER_KIND_PROB))  # noqa: E731
    if trial != "baseline":
        cues = []
        c = float(rng.uniform(20, 28))
        while c < dur_s - 25:
            cues.append(c)
            c += float(rng.uniform(27, 33))
        n_d = min(len(cues), 25) if trial.startswith("exp") else len(cues)
        labels: list[str] = []
        while len(labels) < n_d:
            block = [lab for lab in DISTRACTIONS for _ in range(5)]
            rng.shuffle(block)
            labels += block
        for c, lab in zip(cues[:n_d], labels[:n_d]):
            a = c + float(rng.uniform(0.8, 2.5))
            # an Other motion right before: the distraction then waits until the hand is free
            # (see _simulate), so it starts 1-3 s after the Other motion ends
            if rng.random() < OTHER_NEXT_TO_DISTRACTION_PROB and a > 12.0:
                acts.append((a - float(rng.uniform(3.0, 6.0)), OTHER, draw_other(), False))
            acts.append((a, lab, lab, False))
            if rng.random() < OTHER_NEXT_TO_DISTRACTION_PROB:  # and right after the hand is back
                acts.append((a + 1e-3, OTHER, draw_other(), True))
    rate = subj.other_rate * (1.6 if trial == "baseline" else 1.0)
    n_o = int(rng.poisson(rate * dur_s / 900.0))
    dis = [a for a, lab, _, _ in acts if lab != OTHER]
    for _ in range(n_o):
        for _try in range(20):
            ts = float(rng.uniform(5, dur_s - 15))
            # these come on their own, clear of distractions (the ones next to a distraction are above)
            if all(ts + 9.0 < a or ts > a + 20.0 for a in dis):
                acts.append((ts, OTHER, draw_other(), False))
                break
    acts.sort(key=lambda a: a[0])
    return acts


# ----------------------------------------------------------------------------------------------
# the simulator

_TRIAL_CODE = {name: i for i, name in enumerate(TRIALS + ("drive",))}


def _trial_rng(seed: int, subject_id: int, trial: str) -> np.random.Generator:
    code = _TRIAL_CODE.get(trial)
    if code is None:
        raise ValueError(f"unknown trial {trial!r} (expected one of {', '.join(TRIALS)} or drive)")
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(subject_id), code, 0x3B1]))


def _simulate(subj: Subject, trial: str, rng: np.random.Generator, minutes: float,
              trace: dict | None = None) -> Recording:
    fs = SAMPLE_RATE_HZ
    if not (minutes > 0) or not math.isfinite(minutes):
        raise ValueError("minutes must be a positive number")
    n = int(round(minutes * 60 * fs))
    t = np.arange(n) / fs
    body = _Body(subj)

    steer, lim, a_veh, speed, city, man = _drive(rng, n, subj, fs)
    grip = subj.grip_clock_deg - lim * np.tanh(steer / lim)
    P, thumb_w = body.wheel_pose(grip)
    swivel = np.full(n, subj.swivel_deg) + 3.0 * _band_noise(rng, n, 0.02, 0.3)[:, 0]
    psi_act = np.zeros(n)
    off_wheel = np.zeros(n, bool)

    events: list[Event] = []
    last_end = -1.0
    for ts, label, kind, follows in _schedule(rng, subj, trial, n / fs):
        if follows:  # right after the hand is back on the wheel
            ts = last_end + float(rng.uniform(0.5, 2.5))
        elif ts < last_end + 1.0:  # still busy with the previous activity
            if label == OTHER:
                continue
            ts = last_end + float(rng.uniform(1.0, 3.0))  # the cued task waits until the hand is free
        i0 = int(round(ts * fs))
        if i0 >= n - 2:
            continue
        c = bool(city[i0])
        slow = subj.speed * (subj.city_slowdown * float(np.exp(rng.normal(0, 0.12))) if c else 1.0)
        detail: dict = {"kind": kind} if label == OTHER else {}
        vias = _plan(kind, body, subj, rng, slow, c, detail)
        # detaching from the rim: a quick pull of the wrist back along the forearm and up, blended
        # into the reach (this is what the detector's x axis, along the forearm, picks up first)
        # (some drivers let go gently: then only the reach itself moves the hand)
        if rng.random() < subj.detach_prob:
            _, u0, _ = body.frames(P[i0][None], swivel[i0:i0 + 1])
            pull = -u0[0] * rng.uniform(0.03, 0.07) + np.array([0.0, 0.0, rng.uniform(0.01, 0.03)])
            vias[0].overlap = float(rng.uniform(0.4, 0.8))
            vias.insert(0, _Via(P[i0] + pull, thumb_w[i0], float(swivel[i0]),
                                float(rng.uniform(0.18, 0.3) * math.sqrt(slow))))
        # timing of the superposed submovements
        onsets, ends = [], []
        prev_end, prev_dwell, prev_move = ts, 0.0, 0.0
        for k, v in enumerate(vias):
            on = prev_end + prev_dwell
            if k > 0 and prev_dwell == 0.0 and v.overlap > 0:
                on = prev_end - v.overlap * prev_move
            onsets.append(on)
            ends.append(on + v.move_s)
            prev_end, prev_dwell, prev_move = on + v.move_s, v.dwell_s, v.move_s
        t_end = ends[-1]
        i1 = int(math.ceil(t_end * fs)) + 1
        if i1 >= n:
            continue
        # poses at the via-points
        w_end, th_end = P[i1 - 1], thumb_w[i1 - 1]
        pos = [P[i0]] + [v.pos if v.pos is not None else w_end for v in vias]
        sw = [swivel[i0]] + [v.swivel if v.pos is not None else swivel[i1 - 1] for v in vias]
        th = [thumb_w[i0]] + [v.thumb if v.thumb is not None else th_end for v in vias]
        psi = body.psi_from_thumb(np.array(pos), np.array(sw), np.array(th))
        # BMI limits the forearm rotation away from the wheel posture
        psi_u = [psi[0]]
        for k in range(1, len(psi)):
            dv = _wrap(psi[k] - psi[0])
            if 0 < k < len(psi) - 1:
                dv *= body.rom
                if vias[k - 1].keep_roll_sd is not None:
                    dv = float(rng.normal(0.0, vias[k - 1].keep_roll_sd))
            psi_u.append(psi[0] + dv)
        psi_u[-1] = psi_u[-2] + _wrap(psi[-1] - psi_u[-2])
        sw = [sw[0]] + [sw[0] + body.rom * (s - sw[0]) for s in sw[1:-1]] + [sw[-1]]
        seg_t = t[i0:i1]
        Pp = np.repeat(np.asarray(pos[0])[None], len(seg_t), 0).astype(float)
        ps = np.full(len(seg_t), psi_u[0])
        ss = np.full(len(seg_t), sw[0])
        for k, v in enumerate(vias):
            s = _minjerk((seg_t - onsets[k]) / v.move_s)
            Pp += s[:, None] * (np.asarray(pos[k + 1]) - np.asarray(pos[k]))
            ps += s * (psi_u[k + 1] - psi_u[k])
            ss += s * (sw[k + 1] - sw[k])
            if v.act and v.dwell_s > 0:
                j0 = int(round((ends[k] - ts) * fs))
                m = int(round(v.dwell_s * fs))
                m = max(0, min(m, len(seg_t) - j0))
                dp, dpsi = _micro(v.act, m, rng, subj, fs)
                Pp[j0:j0 + m] += dp
                ps[j0:j0 + m] += dpsi
        P[i0:i1] = Pp
        psi_act[i0:i1] = ps
        swivel[i0:i1] = ss
        off_wheel[i0:i1] = True
        detail["road"] = "city" if c else "highway"
        events.append(Event(round(float(ts), 3), round(float(t_end), 3), label, detail))
        last_end = t_end

    # kinematic chain -> sensor axes
    _, u, nrm = body.frames(P, swivel)
    bvec = np.cross(u, nrm)
    psi_wheel = np.arctan2(np.sum(thumb_w * bvec, 1), np.sum(thumb_w * nrm, 1))
    psi_all = np.where(off_wheel, psi_act, psi_wheel)
    radial = np.cos(psi_all)[:, None] * nrm + np.sin(psi_all)[:, None] * bvec  # towards the thumb
    x_s = u                       # along the forearm, towards the hand
    y_s = radial
    z_s = np.cross(x_s, y_s)      # out of the back of the wrist (the sensor's face)
    sensor_pos = P + SENSOR_OFFSET_M * z_s
    acc_w = np.gradient(np.gradient(sensor_pos, axis=0), axis=0) * fs * fs

    # road vibration: through the wheel when gripping, through the body otherwise
    vib_rms = (0.12 + 0.010 * speed) * np.where(off_wheel, 0.5, 1.0)
    vib = _band_noise(rng, n, 2.0, 25.0, dims=3) * np.array([0.5, 0.4, 1.0]) * vib_rms[:, None]

    f_world = acc_w + a_veh + vib + np.array([0.0, 0.0, G])
    R = np.stack([x_s, y_s, z_s], axis=2)  # world <- sensor, columns are the sensor axes
    f_s = np.einsum("nij,ni->nj", R, f_world)
    if trace is not None:  # internals for tests and diagnostics
        trace.update(wrist=P, swivel=swivel, psi=psi_all, x_axis=x_s, y_axis=y_s, z_axis=z_s, acc_wrist=acc_w,
                     a_vehicle=a_veh, steer_deg=steer, grip_deg=grip, speed=speed, city=city,
                     off_wheel=off_wheel, specific_force_world=f_world, specific_force_sensor=f_s.copy())
    acc = sensor_model(f_s, subj, rng)
    return Recording(acc, events, subj.subject_id, trial, SAMPLE_RATE_HZ, subj, man)


def sensor_model(f_sensor: np.ndarray, subject: Subject, rng: np.random.Generator) -> np.ndarray:
    """Ideal specific force in the nominal sensor frame (n, 3) m/s^2 -> what the accelerometer reports:
    mounting misalignment (subject's + N(0, 1 deg) per trial), scale error, bias (+ N(0, 0.03) per trial),
    white noise, +-16 g clipping and 16-bit quantisation; float32."""
    f = np.asarray(f_sensor, dtype=np.float64)
    mount = _rot_rpy(np.asarray(subject.mount_rpy_deg) + rng.normal(0, [4.0, 1.0, 1.0]))
    f = f @ mount  # M^T f for each row
    f = f * (1.0 + subject.scale_err)
    f = f + np.asarray(subject.bias_mps2) + rng.normal(0, 0.03, 3)
    f = f + subject.noise_mps2 * rng.standard_normal(f.shape)
    f = np.clip(f, -RANGE_MPS2, RANGE_MPS2)
    f = np.round(f / LSB_MPS2) * LSB_MPS2
    return f.astype(np.float32)


def simulate_trial(subject: Subject, trial: str, seed: int, minutes: float = 15.0) -> Recording:
    """One trial of a subject: "baseline" (driving + Other motions) or "exp1".."exp5"
    (five distractions x five repetitions in random order, one cue about every 30 s, plus Other)."""
    if trial not in TRIALS:
        raise ValueError(f"unknown trial {trial!r} (expected one of {', '.join(TRIALS)})")
    return _simulate(subject, trial, _trial_rng(seed, subject.subject_id, trial), float(minutes))


def simulate_drive(minutes: float, seed: int, subject: Subject | None = None) -> Recording:
    """A mixed drive (distractions in random order about every 30 s, plus Other motions)."""
    if subject is None:  # a driver outside any cohort (subject_id 0)
        subject = replace(make_subjects(1, seed=int(seed) + 10_000)[0], subject_id=0)
    return _simulate(subject, "drive", _trial_rng(seed, subject.subject_id, "drive"), float(minutes))


def simulate_cohort(n_subjects: int = 20, seed: int = 0, minutes_per_trial: float = 15.0) -> Iterator[Recording]:
    """Baseline + five experimental trials for each of ``n_subjects`` subjects (a generator)."""
    for subj in make_subjects(n_subjects, seed):
        for trial in TRIALS:
            yield simulate_trial(subj, trial, seed, minutes_per_trial)


__all__ = ["SAMPLE_RATE_HZ", "CLASSES", "Event", "Subject", "Recording", "make_subjects", "simulate_trial",
           "simulate_drive", "simulate_cohort", "sensor_model", "TRIALS", "OTHER_KINDS", "RANGE_MPS2"]
