"""escnn internals: a ``Linear``'s basis-expansion module, its buffers' names, and the
layout of its weights."""

from __future__ import annotations

import copy
from dataclasses import dataclass

import torch
from escnn import nn as enn
from escnn.group import _numerical
from escnn.nn.modules.basismanager import BlocksBasisExpansion


def use_exact_null_space() -> None:
    """Make escnn solve for bases (Clebsch-Gordan coefficients, intertwiners) with
    scipy's exact SVD, also where scikit-learn is installed.

    escnn 1.0.11 switches to scikit-learn's ``randomized_svd`` whenever it can import
    it: then every group whose coefficients are not in escnn's disk cache fails to
    build on scikit-learn >= 1.2, which refuses the ``np.matrix`` escnn passes it
    (seen on a GPU machine whose image has scikit-learn), and where it does run, the
    bases come from a random projection with no seed. Without scikit-learn escnn
    uses scipy's SVD, which is what every test and run of this project used.

    Private: the module attribute ``escnn.group._numerical.randomized_svd``, which
    ``_numerical.null`` reads at each call (``None`` selects ``scipy.linalg.svd``).
    """
    _numerical.randomized_svd = None


use_exact_null_space()  # on import: every module of agents that builds escnn layers imports this one

# The attribute (and so the state-dict key component) of an escnn ``Linear``'s
# basis-expansion module. Private: escnn exposes the module only through the
# read-only property ``Linear.basisexpansion``, and state-dict keys carry the
# attribute's name, so no public name tells its entries apart.
BASIS_EXPANSION = "_basisexpansion"


def is_basis_expansion_key(key: str) -> bool:
    """Whether a state-dict key belongs to an escnn ``Linear``'s basis-expansion
    module: sampled bases and indices that escnn rebuilds with the layer."""
    return BASIS_EXPANSION in key


# The buffers an escnn ``Linear`` registers under its own names: the weight matrix and
# the bias expanded from the coefficients (eval-mode caches, documented as attributes
# but not as state-dict entries), and ``bias_expansion``, the change of basis from the
# bias's coefficients to the output (undocumented). All three are rebuilt with the layer.
LINEAR_BUFFERS = ("matrix", "expanded_bias", "bias_expansion")


def is_linear_buffer(name: str) -> bool:
    """Whether ``name`` (the last component of a state-dict key) is one of the buffers an
    escnn ``Linear`` registers itself, rebuilt with the layer (not its parameters).

    Private: the names escnn's ``Linear.__init__`` and ``Linear.train`` pass to
    ``register_buffer``; escnn lists no public set of them.
    """
    return name in LINEAR_BUFFERS


def bias_expansion(layer: enn.Linear) -> torch.Tensor:
    """[out_size, trivials]: the matrix that maps ``layer.bias`` (one coefficient per
    trivial irrep of the output) to the bias added to the output, ``bias_expansion(layer)
    @ layer.bias``, as escnn's own ``expand_parameters`` computes it. For a layer with a bias.

    Private: the ``Linear.bias_expansion`` buffer, which escnn's documentation does not
    list; its public ``expand_parameters()`` also expands the weight matrix, the cost
    ``agents.nn.layers.EquivariantLinear`` avoids.
    """
    return layer.bias_expansion


def own_basis_expansion(layer: enn.Linear) -> None:
    """Give ``layer`` a deep copy of its basis-expansion module, shared with no other layer.

    escnn caches the modules of its bases and shares them between layers, so
    ``.to()``/``.double()`` on one network would change another's buffers.
    Private: ``Linear._basisexpansion``, the attribute behind the read-only
    ``basisexpansion`` property; escnn has no setter and no option to not share.
    """
    layer._basisexpansion = copy.deepcopy(layer.basisexpansion)


@dataclass(frozen=True)
class BasisBlock:
    """One (input representation, output representation) pair of a
    ``BlocksBasisExpansion`` with a non-empty basis."""

    in_name: str  # the representations' names
    out_name: str
    weights: tuple[int, int]  # [start, stop) of its coefficients in the layer's ``weights``
    sampled_basis: torch.Tensor  # [basis, out_size, in_size, points]: escnn's own buffer


def basis_blocks(expansion: BlocksBasisExpansion) -> list[BasisBlock]:
    """The blocks of ``expansion``, in the order their coefficients lie in the flat
    weight vector. A block's coefficients are ``[n_out, n_in, basis]`` (fields of
    the output, then of the input representation, in their order in the types).

    Private: ``_representations_pairs`` (the non-empty pairs, in weight order),
    ``_weights_ranges``, and the naming of each pair's submodule,
    ``block_expansion_<_escape_pair(pair)>``. The public ``get_basis_info()`` gives
    the same layout as one dict per coefficient, in Python: seconds for a wide
    layer, at every network build (tests/test_compat.py checks that the two agree).
    """
    blocks = []
    for in_name, out_name in expansion._representations_pairs:
        module = getattr(expansion, f"block_expansion_{expansion._escape_pair((in_name, out_name))}")
        start, stop = expansion._weights_ranges[(in_name, out_name)]
        blocks.append(BasisBlock(in_name, out_name, (start, stop), module.sampled_basis))
    return blocks
