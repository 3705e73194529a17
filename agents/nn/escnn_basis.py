"""An escnn ``Linear``'s basis, read as one block per pair of field types: where each
pair's coefficients sit, its sampled basis, and where its blocks go in the weight
(what ``EquivariantLinear`` expands with one GEMM per pair)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import torch
from escnn import nn as enn

from agents.compat.escnn import basis_blocks


@dataclass(frozen=True)
class FieldTypePair:
    """One (input representation, output representation) pair of an escnn ``Linear``:
    where its coefficients sit in the flat parameter vector, and where its blocks go
    in the weight: ``rows``/``cols`` slices when the fields of each type are adjacent,
    else None (the layer keeps channel indices in buffers)."""

    weights: slice
    n_out: int
    n_in: int
    out_size: int
    in_size: int
    rows: slice | None
    cols: slice | None


def field_type_pairs(layer: enn.Linear) -> list[
        tuple[FieldTypePair, torch.Tensor, tuple[torch.Tensor, torch.Tensor] | None]]:
    """The pairs of an escnn ``Linear``'s ``BlocksBasisExpansion`` (the layout of its
    ``forward``), each with its sampled basis as a [basis, out_size x in_size] matrix
    and, when its fields are not adjacent, the channel indices of its rows and columns."""
    expansion = layer.basisexpansion
    if expansion.S != 1:
        raise ValueError(f"expected a 0-dimensional base space (one sample), got {expansion.S}")

    def channels(reprs: list) -> dict[str, list[int]]:
        out, start = {}, 0
        for rep in reprs:
            out.setdefault(rep.name, []).extend(range(start, start + rep.size))
            start += rep.size
        return out

    def adjacent(positions: list[int]) -> bool:
        return positions == list(range(positions[0], positions[-1] + 1))

    # The representations escnn's expansion was built from, in the same order.
    out_reprs, in_reprs = layer.out_type.representations, layer.in_type.representations
    out_channels, in_channels = channels(out_reprs), channels(in_reprs)
    out_count, in_count = Counter(r.name for r in out_reprs), Counter(r.name for r in in_reprs)
    pairs = []
    for block in basis_blocks(expansion):
        in_name, out_name = block.in_name, block.out_name
        basis = block.sampled_basis  # [basis, out_size, in_size, 1]
        start, stop = block.weights
        rows, cols = out_channels[out_name], in_channels[in_name]
        sliced = adjacent(rows) and adjacent(cols)
        pairs.append((FieldTypePair(
            weights=slice(start, stop), n_out=out_count[out_name],
            n_in=in_count[in_name], out_size=basis.shape[1], in_size=basis.shape[2],
            rows=slice(rows[0], rows[-1] + 1) if sliced else None,
            cols=slice(cols[0], cols[-1] + 1) if sliced else None),
            basis.reshape(basis.shape[0], -1).clone(),
            None if sliced else (torch.tensor(rows), torch.tensor(cols))))
    return pairs
