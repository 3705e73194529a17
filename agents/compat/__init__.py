"""Every use of a dependency's private internals, behind one small adapter each.

One module per dependency (``torch``, ``torchrl``, ``escnn``). Each adapter says
which private attribute it touches and why no public API of the pinned version
does the job; ``tests/test_compat.py`` checks each one against the installed
version, so an upgrade that moves an internal fails there, by name, rather than
silently elsewhere. Anything a public API can do is done with it at the call
site, not here. tensordict and gymnasium are used through public APIs only.
"""
