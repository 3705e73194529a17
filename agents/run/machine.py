"""The machine a run runs on, as /proc/cpuinfo describes it: runs are bit-identical
only on one kind of CPU, and OpenBLAS's kernels decide the bases escnn solves for
(docs/checkpoints.md). Without torch: the run queue imports it."""

from __future__ import annotations

import os
import platform
from pathlib import Path


def _cpuinfo() -> dict[str, str]:
    """/proc/cpuinfo's fields, each as it first appears (the first processor's);
    empty where there is none."""
    fields: dict[str, str] = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            fields.setdefault(key.strip().lower(), " ".join(value.split()))
    except OSError:
        pass
    return fields


def cpu_flags() -> set[str]:
    """The x86 CPU's instruction-set flags (``avx2``, ``avx512f``, ...); empty elsewhere."""
    return set(_cpuinfo().get("flags", "").split())


def cpu_model() -> str:
    """The CPU's model name, with its family, model and widest vector instructions
    where /proc/cpuinfo lists them, and OpenBLAS's kernels where they are chosen
    (OPENBLAS_CORETYPE): runs are bit-identical only on the same kind of CPU, "AMD
    EPYC" names several, and the kernels decide the bases escnn solves for
    (docs/checkpoints.md)."""
    fields = _cpuinfo()
    name = next((fields[k] for k in ("model name", "hardware", "cpu model") if fields.get(k)),
                platform.processor() or platform.machine() or "unknown")
    details = []
    if "cpu family" in fields and "model" in fields:
        details.append(f"family {fields['cpu family']} model {fields['model']}")
    flags = cpu_flags()
    if flags:
        details.append("AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "no AVX2")
    if os.environ.get("OPENBLAS_CORETYPE"):
        details.append(f"OPENBLAS_CORETYPE={os.environ['OPENBLAS_CORETYPE']}")
    return f"{name} ({'; '.join(details)})" if details else name
