"""``geomdp-theory``: the paper's reduction tables, computed from the declarations.

Prints markdown: for every task and group, the dimension of S x A, of a
generic orbit and of the quotient, the free parameters of G-equivariant A, B,
K, P (against the unconstrained count), the agent's free parameters (plain vs
equivariant under both width strategies), and, for the LQR view, the largest
violation of the steerability constraints and the LQR oracle's return.

    geomdp-theory [--quick]
"""

from __future__ import annotations

import argparse

import gymnasium
import numpy as np

import geomdp_envs  # noqa: F401
from agents.nn.networks import Architecture, NetworkConfig, build_networks
from geomdp_envs import groups, lqr
from geomdp_envs.theory import dimension_table

TASKS = [
    ("PointMass2D", "GeoMDP/PointMass2D-v0", {}),
    ("PointMass3D, 1 ball", "GeoMDP/PointMass3D-v0", {}),
    ("PointMass3D, 3 balls", "GeoMDP/PointMass3D-v0", {"n_balls": 3}),
    ("Reacher, local", "GeoMDP/Reacher-v0", {"frame": "local"}),
    ("Reacher, global", "GeoMDP/Reacher-v0", {"frame": "global"}),
]
GROUPS = {2: ["SO(2)", "O(2)", "C4", "C8", "C16", "D4", "D8", "D16"],
          3: ["SO(3)", "O(3)", "octahedral", "icosahedral"]}
AGENT_GROUPS = {2: ["D4", "D8"], 3: ["octahedral", "icosahedral"]}
ORACLE_TASKS = [("PointMass2D", "GeoMDP/PointMass2D-v0", {})] + [
    (f"PointMass3D, {n} ball(s), small target", "GeoMDP/PointMass3D-v0",
     {"n_balls": n, "target_size": 0.02}) for n in (1, 3, 5)]


def symmetry_of(env_id: str, kwargs: dict) -> object:
    return gymnasium.make(env_id, **kwargs).unwrapped.symmetry


def reduction_table() -> str:
    rows = ["| task | group | dim S×A | generic orbit | dim (S×A)/G | A | B | K | P (symmetric) |",
            "|---|---|---|---|---|---|---|---|---|"]
    for name, env_id, kwargs in TASKS:
        sym = symmetry_of(env_id, kwargs)
        for group in GROUPS[sym.dim]:
            t = dimension_table(sym, group)
            rows.append(f"| {name} | {group} | {t['dim S×A']} | {t['orbit']} | {t['dim (S×A)/G']} | "
                        + " | ".join(f"{t[m]} / {t[m + ' plain']}" for m in "ABKP") + " |")
    return "\n".join(rows)


def parameter_table(hidden: int, latent: int) -> str:
    rows = [f"| task | agent | free parameters (plain width {hidden}, latent {latent}) "
            "| × plain |", "|---|---|---|---|"]
    sizes = Architecture(hidden_dim=hidden, latent_dim=latent)
    for name, env_id, kwargs in TASKS[:4]:
        sym = symmetry_of(env_id, kwargs)
        plain = sum(build_networks(NetworkConfig(networks=sizes),
                                   sym).parameter_counts().values())
        rows.append(f"| {name} | plain | {plain:,} | 1 |")
        for group in AGENT_GROUPS[sym.dim]:
            for strategy in ("sqrt", "linear"):
                cfg = NetworkConfig(group=group, width_strategy=strategy, networks=sizes)
                n = sum(build_networks(cfg, sym).parameter_counts().values())
                rows.append(f"| {name} | {group} {strategy} | {n:,} | {n / plain:.2f} |")
    return "\n".join(rows)


def lqr_table(n_trials: int) -> str:
    rows = ["| task | group | max rel. error of A(g.s) = D A(s) D⁻¹ | of B | K steerable "
            "| P steerable |", "|---|---|---|---|---|---|"]
    for name, env_id, kwargs in TASKS:
        env = gymnasium.make(env_id, **kwargs)
        env.reset(seed=0)
        sym = env.unwrapped.symmetry
        report = lqr.check_linearization(env, n_trials=n_trials)
        k_err = p_err = "–"
        if env_id != "GeoMDP/Reacher-v0":  # a fixed point exists: the target
            policy = lqr.LQRPolicy(env)
            k_err, p_err = (f"{e:.1e}" for e in gain_steerability(sym, policy, n_trials))
        rows.append(f"| {name} | {sym.exact_group} | {report.max_a_error:.1e} "
                    f"| {report.max_b_error:.1e} | {k_err} | {p_err} |")
    return "\n".join(rows)


def gain_steerability(sym: object, policy: lqr.LQRPolicy, n: int) -> tuple[float, float]:
    """Largest |rho_A(g) K rho_S(g)^-1 - K| and |rho_S(g) P rho_S(g)^T - P|, relative."""
    k_err = p_err = 0.0
    for g in groups.sample(sym.exact_group, np.random.default_rng(0), n):
        rs, ra = sym.observation_matrix(g), sym.action_matrix(g)
        k_err = max(k_err, np.abs(ra @ policy.k @ rs.T - policy.k).max() / np.abs(policy.k).max())
        p_err = max(p_err, np.abs(rs @ policy.p @ rs.T - policy.p).max() / np.abs(policy.p).max())
    return k_err, p_err


def oracle_table(episodes: int) -> str:
    rows = [f"| task | LQR oracle return (mean ± std over {episodes} seeded episodes) |",
            "|---|---|"]
    for name, env_id, kwargs in ORACLE_TASKS:
        env = gymnasium.make(env_id, **kwargs)
        env.reset(seed=0)
        mean, std = lqr.evaluate_policy(env, lqr.LQRPolicy(env), range(episodes))
        rows.append(f"| {name} | {mean:.1f} ± {std:.1f} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer trials and episodes")
    parser.add_argument("--hidden", type=int, default=512, help="plain width (TD-MPC: 512)")
    parser.add_argument("--latent", type=int, default=50, help="plain latent size (TD-MPC: 50)")
    args = parser.parse_args(argv)
    print("## Dimensions: equivariant / unconstrained\n")
    print(reduction_table())
    print("\n## Agent parameters\n")
    print(parameter_table(args.hidden, args.latent))
    print("\n## LQR: steerability of the linearisation, gain and value matrix\n")
    print(lqr_table(4 if args.quick else 16))
    print("\n## LQR oracle\n")
    print(oracle_table(3 if args.quick else 20))


if __name__ == "__main__":
    main()
