"""Options of bsp-synth: presets, the original generator's YAML keys, validation.

A :class:`SynthConfig` holds every parameter that influences the output; it is written to
``config.yaml`` next to ``data.csv`` (worker count and paths are not in it: they never
change the bytes produced).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Profile", "SynthConfig", "PRESETS", "DEFAULT_PROFILES", "load_yaml_config",
           "make_config"]

AGES = ("adult", "child")
GENDERS = ("female", "male")


@dataclass(frozen=True)
class Profile:
    """A pedestrian profile: (age, gender) and N(mean, std) speeds in m/s.

    The recorder drew every clip's constant target speed from ``crossing_speed``
    (docs/dataset-format.md, "6. How the recorder placed cameras and walkers");
    ``walking_speed`` is kept because the original configs carry it.
    """

    age: str
    gender: str
    walking_speed: tuple
    crossing_speed: tuple

    @property
    def name(self) -> str:
        return f"{self.age}_{self.gender}"

    def to_yaml(self) -> list:
        return [self.age, self.gender, list(self.walking_speed), list(self.crossing_speed)]


# The original generator's ExamplePedestrianProfiles (docs/dataset-format.md,
# "6. How the recorder placed cameras and walkers" for the speeds used).
DEFAULT_PROFILES = {
    "adult_female": Profile("adult", "female", (1.19, 0.19), (1.45, 0.23)),
    "adult_male": Profile("adult", "male", (1.27, 0.21), (1.47, 0.24)),
    "child_female": Profile("child", "female", (0.9, 0.19), (0.9, 0.23)),
    "child_male": Profile("child", "male", (0.9, 0.21), (0.9, 0.24)),
}

PRESETS = {
    # Small enough for tests and `make demo` (seconds on 2 cores): 5 s clips, so that some
    # crossing walkers reach the road, and enough of them (20) that the default conversion
    # (L = 30) puts crossing and non-crossing clips in each of train, val and test.
    "sample": dict(number_of_clips=20, clip_length_in_frames=150, camera_image_size=(640, 240)),
    # The report's experiments on 2 cores (under 10 min with media): the published camera
    # and image size, 10 s clips (most crossing events fall in the first 10 s, so most
    # crossing walkers reach the road), 160 of them: ~500 clips in the benchmark's
    # time-to-event windows and ~900 default clips (docs/synth.md).
    "medium": dict(number_of_clips=160, clip_length_in_frames=300,
                   camera_image_size=(1600, 600)),
    # The published CARLA-BSP shape (docs/dataset-format.md, "2. data.csv").
    "full": dict(number_of_clips=396, clip_length_in_frames=900, camera_image_size=(1600, 600)),
}


@dataclass(frozen=True)
class SynthConfig:
    """Every parameter that shapes a generated dataset (see docs/synth.md)."""

    preset: str = "sample"
    seed: int = 22752
    number_of_clips: int = 4
    clip_length_in_frames: int = 150
    camera_image_size: tuple = (640, 240)  # (width, height)
    camera_fov: float = 90.0
    fps: int = 30
    batch_size: int = 1  # consecutive clips sharing one street layout (one "map")
    pedestrian_distributions: tuple = tuple((p, 0.25) for p in DEFAULT_PROFILES.values())
    camera_position_distributions: tuple = (((-7.0, 2.0), (0.0, 0.25), (1.0, 0.25)),)
    crossing_probability: float = 0.5
    waypoint_radius: float = 1.0
    parallel_max_distance: float = 5.0
    # Look-at point: the nearest driving-lane point, shifted along the lane's travel
    # direction by N(mean, std) metres (the original's "shifted driving lane waypoint").
    look_at_shift: tuple = (3.0, 3.0)
    apng_drop_duplicates: bool = False
    # data.csv only (media paths recorded, no MP4/APNG written); data.csv is byte-identical
    # to the full mode's: it changes no random draw.
    poses_only: bool = False
    # each walker's bone offsets scaled by a seeded factor in [1 - v, 1 + v] (0: every walker
    # has its profile's reference skeleton exactly); data.csv stays self-consistent
    bone_length_variation: float = 0.0
    video_bitrate: int = 1_000_000
    video_preset: str = "veryfast"
    motion: str | None = None  # BVH / FBX / glTF file driving the body instead of the gait
    motion_sha256: str | None = None
    world_map: str = "/Game/bsp_synth/Maps/ProceduralStreet"
    extra: dict = field(default_factory=dict)

    @property
    def width(self) -> int:
        return int(self.camera_image_size[0])

    @property
    def height(self) -> int:
        return int(self.camera_image_size[1])

    def to_yaml_dict(self, version: str) -> dict:
        """Plain-YAML form of every parameter used (written to ``config.yaml``)."""
        return {
            "version": version,
            "generator": "bsp-synth",
            "preset": self.preset,
            "seed": self.seed,
            "number_of_clips": self.number_of_clips,
            "clip_length_in_frames": self.clip_length_in_frames,
            "fps": self.fps,
            "camera_fov": self.camera_fov,
            "camera_image_size": [self.width, self.height],
            "batch_size": self.batch_size,
            "pedestrian_distributions": [[p.to_yaml(), w]
                                         for p, w in self.pedestrian_distributions],
            "camera_position_distributions": [[list(d) for d in cam]
                                              for cam in self.camera_position_distributions],
            "crossing_probability": self.crossing_probability,
            "waypoint_radius": self.waypoint_radius,
            "parallel_max_distance": self.parallel_max_distance,
            "look_at_shift": list(self.look_at_shift),
            "apng_drop_duplicates": self.apng_drop_duplicates,
            "poses_only": self.poses_only,
            "bone_length_variation": self.bone_length_variation,
            "video": {"codec": "h264", "pix_fmt": "yuv420p", "bitrate": self.video_bitrate,
                      "preset": self.video_preset},
            "segmentation": {"format": "apng", "palette": "cityscapes", "indices": "carla"},
            "motion": self.motion,
            "motion_sha256": self.motion_sha256,
            "world_map": self.world_map,
        }


def _speed(x, what: str) -> tuple:
    if not (isinstance(x, (list, tuple)) and len(x) == 2):
        raise ValueError(f"{what}: expected [mean, std], got {x!r}")
    mean, std = float(x[0]), float(x[1])
    if not (mean > 0 and std >= 0 and math.isfinite(mean) and math.isfinite(std)):
        raise ValueError(f"{what}: need mean > 0 and std >= 0, got {x!r}")
    return (mean, std)


def parse_profiles(entries) -> tuple:
    """``pedestrian_distributions`` as in the original generator: a list of
    ``[profile, weight]`` where profile is a name (``adult_female`` ...) or
    ``[age, gender, [walk_mean, walk_std], [cross_mean, cross_std]]``. Weights are
    normalised to sum to 1."""
    if not isinstance(entries, (list, tuple)) or not entries:
        raise ValueError("pedestrian_distributions: expected a non-empty list of "
                         "[profile, weight]")
    out = []
    for i, entry in enumerate(entries):
        if isinstance(entry, dict):
            entry = (entry.get("profile"), entry.get("weight"))
        if not (isinstance(entry, (list, tuple)) and len(entry) == 2):
            raise ValueError(f"pedestrian_distributions[{i}]: expected [profile, weight], "
                             f"got {entry!r}")
        prof, weight = entry
        if isinstance(prof, Profile):
            p = prof
        elif isinstance(prof, str):
            if prof not in DEFAULT_PROFILES:
                raise ValueError(f"pedestrian_distributions[{i}]: unknown profile {prof!r}; "
                                 f"allowed {sorted(DEFAULT_PROFILES)}")
            p = DEFAULT_PROFILES[prof]
        elif isinstance(prof, (list, tuple)) and len(prof) == 4:
            age, gender = prof[0], prof[1]
            if age not in AGES or gender not in GENDERS:
                raise ValueError(f"pedestrian_distributions[{i}]: age must be one of {AGES} "
                                 f"and gender one of {GENDERS}, got {age!r}, {gender!r}")
            p = Profile(age, gender, _speed(prof[2], f"pedestrian_distributions[{i}] walking"),
                        _speed(prof[3], f"pedestrian_distributions[{i}] crossing"))
        else:
            raise ValueError(f"pedestrian_distributions[{i}]: profile must be a name or "
                             f"[age, gender, [mean, std], [mean, std]], got {prof!r}")
        w = float(weight)
        if not (w >= 0 and math.isfinite(w)):
            raise ValueError(f"pedestrian_distributions[{i}]: weight must be >= 0, got {weight!r}")
        out.append((p, w))
    total = sum(w for _, w in out)
    if total <= 0:
        raise ValueError("pedestrian_distributions: weights must not all be zero")
    return tuple((p, w / total) for p, w in out)


def parse_camera_positions(entries) -> tuple:
    """``camera_position_distributions``: a list of cameras, each three [mean, std] pairs
    (x, y, z offsets in the look-at lane frame). bsp-synth records camera 0 only."""
    if not isinstance(entries, (list, tuple)) or not entries:
        raise ValueError("camera_position_distributions: expected a non-empty list of "
                         "cameras, each [[mean, std], [mean, std], [mean, std]]")
    cams = []
    for i, cam in enumerate(entries):
        if not (isinstance(cam, (list, tuple)) and len(cam) == 3):
            raise ValueError(f"camera_position_distributions[{i}]: expected 3 [mean, std] "
                             f"pairs (x, y, z), got {cam!r}")
        pairs = []
        for k, d in enumerate(cam):
            if not (isinstance(d, (list, tuple)) and len(d) == 2) or float(d[1]) < 0:
                raise ValueError(f"camera_position_distributions[{i}][{k}]: expected "
                                 f"[mean, std >= 0], got {d!r}")
            pairs.append((float(d[0]), float(d[1])))
        cams.append(tuple(pairs))
    if len(cams) > 1:
        raise ValueError("camera_position_distributions: bsp-synth records one camera "
                         f"(camera.idx 0), got {len(cams)}")
    return tuple(cams)


_YAML_KEYS = {"number_of_clips", "clip_length_in_frames", "pedestrian_distributions",
              "camera_position_distributions", "camera_distances_distributions", "camera_fov",
              "camera_image_size", "batch_size", "seed", "crossing_probability",
              "waypoint_radius", "parallel_max_distance", "look_at_shift",
              "apng_drop_duplicates", "outputs_dir", "overwrite", "failure_multiplier",
              "waypoint_jitter_scale", "video_preset", "video_bitrate", "poses_only",
              "bone_length_variation"}
X264_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow",
                "slower", "veryslow")


def load_yaml_config(path) -> dict:
    """Reads a generator YAML (the original keys plus bsp-synth's) into option overrides."""
    import yaml

    with open(path, "r", encoding="utf-8") as fh:
        doc = yaml.safe_load(fh) or {}
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: expected a mapping of options, got {type(doc).__name__}")
    unknown = sorted(set(doc) - _YAML_KEYS)
    if unknown:
        raise ValueError(f"{path}: unknown keys {unknown}; allowed {sorted(_YAML_KEYS)}")
    out = dict(doc)
    # Keys of the original generator that have no meaning here.
    for k in ("outputs_dir", "overwrite", "failure_multiplier"):
        out.pop(k, None)
    if "camera_distances_distributions" in out:  # the original's later name
        out.setdefault("camera_position_distributions",
                       out.pop("camera_distances_distributions"))
    if "waypoint_jitter_scale" in out:  # scales the spread of the look-at shift
        mean, std = SynthConfig.look_at_shift
        out.setdefault("look_at_shift", (mean, std * float(out.pop("waypoint_jitter_scale"))))
    return out


def _positive_int(v, name: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or int(v) != v or v < 1:
        raise ValueError(f"{name}: expected a positive integer, got {v!r}")
    return int(v)


def parse_size(v) -> tuple:
    """'1600x600', (1600, 600) or [1600, 600] -> (1600, 600); both even (yuv420p)."""
    if isinstance(v, str):
        parts = v.lower().replace(",", "x").strip("()[] ").split("x")
    else:
        parts = list(v) if isinstance(v, (list, tuple)) else []
    try:
        w, h = (int(p) for p in parts)
    except (TypeError, ValueError):
        raise ValueError(f"size: expected WIDTHxHEIGHT, got {v!r}") from None
    if w < 16 or h < 16 or w % 2 or h % 2 or w > 8192 or h > 8192:
        raise ValueError(f"size: width and height must be even and in [16, 8192] "
                         f"(H.264 yuv420p), got {w}x{h}")
    return (w, h)


def make_config(preset: str = "sample", overrides: dict | None = None) -> SynthConfig:
    """Resolves preset defaults, then config-file / CLI overrides, and validates them."""
    if preset not in PRESETS:
        raise ValueError(f"preset: expected one of {sorted(PRESETS)}, got {preset!r}")
    opts: dict[str, Any] = {"preset": preset, **PRESETS[preset]}
    for k, v in (overrides or {}).items():
        if v is not None:
            opts[k] = v
    known = {f.name for f in dataclasses.fields(SynthConfig)}
    unknown = sorted(set(opts) - known)
    if unknown:
        raise ValueError(f"unknown options {unknown}; allowed {sorted(known)}")
    opts["number_of_clips"] = _positive_int(opts["number_of_clips"], "number_of_clips")
    opts["clip_length_in_frames"] = _positive_int(opts["clip_length_in_frames"],
                                                  "clip_length_in_frames")
    opts["batch_size"] = _positive_int(opts.get("batch_size", 1), "batch_size")
    opts["camera_image_size"] = parse_size(opts["camera_image_size"])
    fov = float(opts.get("camera_fov", 90.0))
    if not 10.0 <= fov <= 170.0:
        raise ValueError(f"camera_fov: expected degrees in [10, 170], got {fov!r}")
    opts["camera_fov"] = fov
    seed = opts.get("seed", SynthConfig.seed)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
    if "pedestrian_distributions" in opts:
        opts["pedestrian_distributions"] = parse_profiles(opts["pedestrian_distributions"])
    if "camera_position_distributions" in opts:
        opts["camera_position_distributions"] = parse_camera_positions(
            opts["camera_position_distributions"])
    p = float(opts.get("crossing_probability", 0.5))
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"crossing_probability: expected [0, 1], got {p!r}")
    opts["crossing_probability"] = p
    for k in ("waypoint_radius", "parallel_max_distance"):
        if k in opts and not float(opts[k]) >= 0:
            raise ValueError(f"{k}: expected a non-negative number, got {opts[k]!r}")
    v = opts.get("bone_length_variation", 0.0)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v < 0.5:
        raise ValueError(f"bone_length_variation: expected a number in [0, 0.5), got {v!r}")
    opts["bone_length_variation"] = float(v)
    if not isinstance(opts.get("poses_only", False), bool):
        raise ValueError(f"poses_only: expected true or false, got {opts['poses_only']!r}")
    if opts.get("video_preset", "veryfast") not in X264_PRESETS:
        raise ValueError(f"video_preset: expected one of {X264_PRESETS}, "
                         f"got {opts['video_preset']!r}")
    if "video_bitrate" in opts:
        opts["video_bitrate"] = _positive_int(opts["video_bitrate"], "video_bitrate")
    if "look_at_shift" in opts:
        shift = opts["look_at_shift"]
        if not (isinstance(shift, (list, tuple)) and len(shift) == 2 and float(shift[1]) >= 0):
            raise ValueError(f"look_at_shift: expected [mean, std >= 0] metres, got {shift!r}")
        opts["look_at_shift"] = (float(shift[0]), float(shift[1]))
    return SynthConfig(**opts)
