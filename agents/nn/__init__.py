"""Networks, plain or G-equivariant from one definition: the agent's groups as escnn
groups (``escnn_groups``), layers that take plain sizes or field types (``layers``,
``fourier``, ``spectral``, ``activations``) and TD-MPC's networks (``networks``)."""
