"""Every use of a dependency's private internals, behind one small adapter each.

One module per dependency (``torch``, ``torchrl``, ``escnn``). Each adapter says
which private attribute it touches and why no public API of the pinned version
does the job; ``tests/test_compat.py`` checks each one against the installed
version, so an upgrade that moves an internal fails there, by name, rather than
silently elsewhere. Anything a public API can do is done with it at the call
site, not here (``TDMPCAgent.target_lag``'s norms use the public
``torch.nn.utils.get_total_norm``, which the tests check gives the numbers of the
private foreach ops it replaced, bit for bit). gymnasium's internals (a MuJoCo
env's ``_get_obs``, ``Env._np_random_seed``) are used by ``geomdp_envs``, which
does not import ``agents``: their adapter is ``geomdp_envs/compat.py``, checked in
the same tests. tensordict, MuJoCo and dm_control are used through public APIs only.
"""
