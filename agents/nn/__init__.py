"""Networks, plain or G-equivariant from one definition: the agent's groups as escnn
groups (``escnn_groups``), plain sizes or field types and their arithmetic (``layout``),
layers that take them (``layers``, ``fourier``, ``spectral``, ``activations``), the
expansion of escnn's bases into weights (``escnn_basis``, ``expansion``), walking and
detaching a network's parameters (``parameters``) and TD-MPC's networks (``networks``)."""
