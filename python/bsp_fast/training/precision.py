"""``--precision``: what ``auto`` picks, decided on this machine, and the warning for bf16
on a CPU without bf16 instructions (docs/training.md, "Precision").

``auto`` is float32 on a GPU without bf16 and on a CPU without native bf16 (no
AVX512-BF16/AMX: bf16 is emulated there, measured 5-17x slower). On a GPU with bf16
(where the small models here ran at x0.68-0.98 of float32's speed in bf16 autocast on an
H100) and on a CPU with native bf16 it is decided per (model, CPU or GPU model, thread
count, torch version; a CPU by its model name, flags and kernels' ISA) by a short timed
probe of the run's own model on one of its own train batches: a few training steps
(forward, loss, backward, optimiser step) in float32 and in bf16 autocast, alternating,
timed in CPU time with one thread (wall time with more, or on a GPU), on copies of the
network (the run's weights and random state are untouched); bf16-mixed when its median
step is at least 10 % faster. The answer is cached in
``$XDG_CACHE_HOME/bsp_fast/precision.json`` (``~/.cache``; ``BSP_PRECISION_CACHE`` names
another file), so a machine decides once and every later run there agrees, and each run
records what was picked and why in its ``config.yaml`` (``resolved: precision_reason``);
a resumed run keeps that answer. ``BSP_PRECISION_PROBE=0`` turns the probe off: then the
models' ``cpu_bf16_faster`` attributes (the earlier measurements) decide.
``--precision`` set to anything but ``auto`` is used as given.
"""
from __future__ import annotations

import json
import os
import platform
import statistics
import time
from pathlib import Path

__all__ = ["resolve_precision", "decide_precision", "native_bf16", "check_precision",
           "probe_cache_path", "probe_key", "probe_clock", "time_steps", "MARGIN", "cpu_flags",
           "cpu_summary", "cpu_kernels", "kept_precision", "run_model_key", "machine_record"]

#: the CPU flags that decide bf16's speed on a CPU, as benchmarks report them
SPEED_FLAGS = ("avx2", "avx512f", "avx512_bf16", "amx_bf16", "amx_tile")

#: bf16 is picked when its median training step is at most this fraction of float32's
MARGIN = 0.9
_STEPS, _WARMUP = 5, 2


def resolve_precision(precision: str, accelerator: str, model=None) -> str:
    """``auto`` -> bf16-mixed on a GPU that supports it; on a CPU with native bf16
    (AVX512-BF16/AMX) bf16-mixed for a ``model`` (class or instance) whose
    ``cpu_bf16_faster`` is set (measured faster there); else 32. Without a probe: what a
    run falls back on (:func:`decide_precision` probes, on a GPU too)."""
    return decide_precision(precision, accelerator, model)[0]


def decide_precision(precision: str, accelerator: str, model=None, *, probe=None,
                     key: str | None = None) -> tuple:
    """``(precision, reason)``. ``probe``: a function ``bf16 -> seconds per step`` on the
    run's model and batch (see :func:`time_steps`); with it, and the probe not turned off,
    a CPU with native bf16 decides by measurement, cached under ``key``."""
    if precision != "auto":
        return precision, "given (--precision)"
    import torch

    gpu = accelerator == "gpu" or (accelerator == "auto" and torch.cuda.is_available())
    probing = probe is not None and key is not None and os.environ.get(
        "BSP_PRECISION_PROBE", "1") != "0"
    if gpu and torch.cuda.is_available() and torch.cuda.is_bf16_supported():
        # measured, as on a CPU: the probe's steps of the small models here ran x0.68-0.98
        # as fast under bf16 autocast on an H100 (docs/performance.md)
        if probing:
            return _probed(key, probe, "this GPU")
        return "bf16-mixed", "auto: a GPU with bf16 (the probe is off)"
    if gpu:
        return "32", "auto: a GPU without bf16"
    if not native_bf16("cpu"):
        return "32", ("auto: this CPU has no native bf16 (no AVX512-BF16/AMX), where bf16 "
                      "is emulated and several times slower")
    if not probing:
        faster = bool(getattr(model, "cpu_bf16_faster", False))
        return ("bf16-mixed" if faster else "32"), (
            "auto: native bf16; the model's measured policy (cpu_bf16_faster="
            f"{faster}; the probe is off)")
    return _probed(key, probe)


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def cpu_flags() -> list:
    """Which of :data:`SPEED_FLAGS` this CPU has (``/proc/cpuinfo``; [] where unreadable)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return []
    have = next((set(ln.split(":", 1)[1].split()) for ln in text.splitlines()
                 if ln.startswith("flags")), set())
    return [f for f in SPEED_FLAGS if f in have]


def cpu_summary() -> str:
    """``"<model name>; avx2 avx512f avx512_bf16"``: the line every benchmark prints so that
    its numbers name the kind of CPU they were measured on."""
    return f"{_cpu_name()}; {' '.join(cpu_flags()) or 'none of ' + ' '.join(SPEED_FLAGS)}"


def machine_record(accelerator: str = "cpu") -> dict:
    """What a run's numbers were made on, for its config.yaml and the tables: the CPU's
    model name and bf16-relevant flags (bf16 is 5-17x slower without them), its core
    count and, where the run may use one, the GPU's name."""
    gpu = None
    if accelerator != "cpu":
        import torch

        gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    return {"cpu": _cpu_name(), "cpu_flags": cpu_flags(), "cpus": os.cpu_count(), "gpu": gpu}


def cpu_kernels() -> str:
    """The CPU as a probe's answer depends on it: its model name, its bf16-relevant flags
    and the instruction set torch's kernels use (``ATEN_CPU_CAPABILITY`` and oneDNN's
    ``ONEDNN_MAX_CPU_ISA`` can lower it). The model name alone is not enough: a virtual
    machine's can be just "AMD EPYC" on AVX2-only and on AVX512-BF16 generations, and an
    answer cached on one must not be reused on the other (bf16 5-17x slower there)."""
    import torch

    isa = os.environ.get("ONEDNN_MAX_CPU_ISA") or os.environ.get("DNNL_MAX_CPU_ISA")
    return (f"{_cpu_name()} [{' '.join(cpu_flags()) or '-'}; kernels "
            f"{torch.backends.cpu.get_cpu_capability()}{f', oneDNN {isa}' if isa else ''}]")


def kept_precision(saved: dict):
    """``(precision, why)`` a resumed run keeps: the one its ``auto`` picked when it
    started (its config.yaml's ``resolved``), or None. Asking again could answer otherwise
    (another machine, a cleared cache, a probe near its margin) and change the precision
    in the middle of the run."""
    saved = saved or {}
    resolved = saved.get("resolved") or {}
    pick, why = resolved.get("precision"), resolved.get("precision_reason") or ""
    if saved.get("precision") != "auto" or pick not in ("32", "bf16-mixed"):
        return None
    prefix = "auto, kept from the run's start: "
    return pick, why if why.startswith(prefix) else prefix + why


def probe_cache_path() -> Path:
    given = os.environ.get("BSP_PRECISION_CACHE")
    if given:
        return Path(given)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "bsp_fast" / "precision.json"


def run_model_key(cfg: dict, hparams: dict, batch: int, speed_revision=None) -> str:
    """The model part of a run's :func:`probe_key`: task/model, hyper-parameters, batch
    size and the model's ``speed_revision`` ("speed N": its step times changed)."""
    return (f"{cfg['task']}/{cfg['model']} {json.dumps(hparams, sort_keys=True, default=str)} "
            f"batch {batch}" + (f" speed {speed_revision}" if speed_revision else ""))


def probe_key(model_key: str, threads: int, device: str = "cpu") -> str:
    """What a probe's answer holds for: the model (task/name and hyper-parameters), the CPU
    (:func:`cpu_kernels`; or the GPU's model, ``device="cuda"``), the thread count and
    torch's version."""
    import torch

    where = cpu_kernels() if device == "cpu" else torch.cuda.get_device_name()
    # "probe 2": steps alternating and timed by probe_clock; answers of the first probe
    # (each precision's steps in a row, wall time) are not reused
    return (f"{model_key} | {where} | {threads} thread(s) | torch {torch.__version__}"
            " | probe 2")


def _read_cache(path: Path) -> dict:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def _probed(key: str, probe, where: str = "this CPU") -> tuple:
    """Under an exclusive lock beside the cache: runs started together (bsp-reproduce's
    seeds in parallel processes) wait for the first one's probe and read its answer, so
    the seeds of a row never train in different precisions (nor time each other)."""
    import contextlib
    import fcntl

    path = probe_cache_path()
    with contextlib.ExitStack() as stack:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            lock = stack.enter_context(open(path.with_name(path.name + ".lock"), "a"))
            fcntl.flock(lock, fcntl.LOCK_EX)
        except OSError:
            pass  # no lock where none can be made: each run probes for itself
        return _probed_locked(path, key, probe, where)


def _probed_locked(path: Path, key: str, probe, where: str = "this CPU") -> tuple:
    cached = _read_cache(path).get(key)
    if isinstance(cached, dict) and cached.get("precision") in ("32", "bf16-mixed"):
        return cached["precision"], cached.get("reason", "") + f" (cached in {path})"
    fp32, bf16 = probe(False), probe(True)
    pick = "bf16-mixed" if bf16 <= MARGIN * fp32 else "32"
    clock = probe_clock()[1] if where == "this CPU" else "wall time"
    reason = (f"auto: probe on {where}, median step ({clock}) float32 "
              f"{fp32 * 1e3:.1f} ms, bf16 {bf16 * 1e3:.1f} ms (x{fp32 / bf16:.2f}); bf16 "
              f"needs x{1 / MARGIN:.2f}")
    try:  # a cache that cannot be written only costs the next run its probe
        from ..atomic import write_text

        doc = _read_cache(path)
        doc[key] = {"precision": pick, "reason": reason, "fp32_s": fp32, "bf16_s": bf16,
                    "when": time.strftime("%Y-%m-%d %H:%M:%S")}
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text(path, json.dumps(doc, indent=1, sort_keys=True) + "\n")
    except OSError:
        pass
    return pick, reason


def probe_clock() -> tuple:
    """``(clock, name)`` the probe times steps with: with one torch thread the process's CPU
    time, which other processes sharing the cores barely change (a probe timed in wall
    seconds beside two other trainings once measured bf16 at x0.84 of float32 for a
    network measured at x1.33 on a quieter machine); with more threads wall time, since
    their waiting is part of what a step costs."""
    import torch

    if torch.get_num_threads() == 1:
        return time.process_time, "CPU time"
    return time.perf_counter, "wall time"


def time_steps(net, batch: dict, steps: int = _STEPS, warmup: int = _WARMUP,
               device: str = "cpu"):
    """A probe for :func:`decide_precision`: ``bf16 -> median seconds`` of training steps
    (forward, loss, backward, SGD step) of a copy of ``net`` on ``batch``, timed by
    :func:`probe_clock`; the caller's weights and random state are untouched. The first
    call measures both precisions, their steps alternating (float32, bf16, float32, ...),
    so that a change of the machine's load during the probe falls on both alike; later
    calls return those medians. ``device="cuda"``: the copies and the batch moved there,
    wall time with the GPU's queue drained before each reading."""
    import copy

    import torch

    if device != "cpu":
        batch = {k: v.to(device) if isinstance(v, torch.Tensor) else v for k, v in batch.items()}

        def clock() -> float:
            torch.cuda.synchronize()
            return time.perf_counter()
    else:
        clock = probe_clock()[0]

    def step(model, opt, bf16: bool) -> float:
        t0 = clock()
        with torch.autocast(device, dtype=torch.bfloat16, enabled=bf16):
            loss = model.loss(model.forward_batch(batch), batch)
        opt.zero_grad(set_to_none=True)
        loss.float().backward()
        opt.step()
        return clock() - t0

    medians: dict = {}

    def measure() -> None:
        with torch.random.fork_rng(devices=[] if device == "cpu" else None):
            pairs = []
            for bf16 in (False, True):  # a copy per precision: their caches stay apart
                model = copy.deepcopy(net).to(device).train()
                pairs.append((model, torch.optim.SGD(
                    [p for p in model.parameters() if p.requires_grad], lr=0.0)))
            firsts = [step(m, o, bf16) for (m, o), bf16 in zip(pairs, (False, True))]
            # warm-up; a slow model (> 1 s a step) gets 1 warm-up step and 2 timed ones
            n_warm, n = (1, min(steps, 2)) if max(firsts) > 1.0 else (warmup, steps)
            times: dict = {False: [], True: []}
            for k in range(n_warm - 1 + n):
                for (m, o), bf16 in zip(pairs, (False, True)):
                    t = step(m, o, bf16)
                    if k >= n_warm - 1:
                        times[bf16].append(t)
            medians.update({b: statistics.median(v) for b, v in times.items()})

    def run(bf16: bool) -> float:
        if not medians:
            measure()
        return medians[bool(bf16)]
    return run


def native_bf16(accelerator: str) -> bool:
    """Whether bf16 arithmetic runs natively where ``accelerator`` trains: a CUDA device,
    or a CPU with AVX512-BF16/AMX."""
    import torch

    if accelerator != "cpu" and torch.cuda.is_available():
        return True
    from ..models import lstm

    return lstm.cpu_bf16()


def check_precision(precision: str, accelerator: str) -> None:
    """bf16 on a CPU without bf16 instructions (AVX512-BF16/AMX): allowed, with a warning.
    oneDNN then converts to and from bf16 around float32 arithmetic (measured 5-17x
    slower than 32 on an AVX2 CPU) and has no bf16 LSTM kernel, so the models' LSTM
    layers run in float32 inside autocast (``models.lstm``)."""
    import warnings

    if precision.startswith("bf16") and not native_bf16(accelerator):
        warnings.warn(f"--precision {precision} on a CPU without bf16 instructions "
                      "(AVX512-BF16/AMX): expect it to be several times slower than "
                      "--precision 32 (docs/training.md, Precision); LSTM layers run in "
                      "float32", UserWarning, stacklevel=2)
