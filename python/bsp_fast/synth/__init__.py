"""bsp-synth: a simulator-free generator of CARLA-BSP-format datasets.

``generate(out_dir, preset="sample", ...)`` writes data.csv, clips/<id>-0.mp4,
clips/<id>-1.apng and config.yaml exactly in the format of docs/dataset-format.md,
"1. Files on disk" to "3. Media": a procedural street ray-cast on the CPU, a pedestrian
walking (procedural gait or a retargeted BVH/FBX/glTF animation) on the CARLA skeleton,
poses consistent through the core's forward kinematics and projection. See docs/synth.md.
"""
from __future__ import annotations

from .config import DEFAULT_PROFILES, PRESETS, Profile, SynthConfig, make_config
from .generate import generate

__all__ = ["generate", "make_config", "SynthConfig", "Profile", "PRESETS", "DEFAULT_PROFILES"]
