"""Layouts: what a feature vector is made of, and the arithmetic on them.

A *layout* describes a feature vector: an ``int`` (plain R^n, no group action)
or an escnn ``FieldType`` (a direct sum of representations of a group). The
layers (``agents.nn.layers``) take layouts, so one network definition serves
both; these functions answer what the layers and networks ask of one: its size,
its fields, concatenation, and which nonlinearities and maps are exact on it.
"""

from __future__ import annotations

from escnn import nn as enn

Layout = int | enn.FieldType


def layout_size(layout: Layout) -> int:
    return layout if isinstance(layout, int) else layout.size


def field_sizes(layout: Layout) -> list[int]:
    """Sizes of the fields whose coordinates share a LayerNorm scale and shift."""
    if isinstance(layout, int):
        return [1] * layout
    return [rep.size for rep in layout.representations]


def concat(a: Layout, b: Layout) -> Layout:
    """The layout of ``torch.cat([x_a, x_b], -1)``."""
    if isinstance(a, int) and isinstance(b, int):
        return a + b
    if isinstance(a, int) or isinstance(b, int):
        raise TypeError("cannot concatenate a plain and an equivariant layout")
    return a + b


def is_pointwise(layout: Layout) -> bool:
    """Whether pointwise nonlinearities and field-tied LayerNorm are exact on it."""
    return isinstance(layout, int) or all(
        "pointwise" in rep.supported_nonlinearities for rep in layout.representations)


def is_regular(layout: Layout) -> bool:
    """Whether a layout is made only of regular fields of a finite group (a hidden
    layer of an equivariant net; continuous groups' hidden fields are band-limited)."""
    if isinstance(layout, int):
        return False
    regular, rest = regular_prefix(layout)
    return regular is not None and rest is None


def regular_prefix(layout: enn.FieldType) -> tuple[enn.FieldType | None, enn.FieldType | None]:
    """(the leading regular fields, the fields after them), as field types (None if empty)."""
    reps = layout.representations
    regular_name = None if layout.gspace.fibergroup.continuous else (
        layout.gspace.fibergroup.regular_representation.name)
    n = next((i for i, rep in enumerate(reps) if rep.name != regular_name), len(reps))
    return (enn.FieldType(layout.gspace, reps[:n]) if n else None,
            enn.FieldType(layout.gspace, reps[n:]) if n < len(reps) else None)
