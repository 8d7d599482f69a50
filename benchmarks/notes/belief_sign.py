"""Diagnostic: does AOC's decision have the expert's torque sign, per ``--belief`` kind?

On rows of the noiseless swing-up controller in the *normal* system of a pendulum-het corpus
(rows with |torque| > 0.3, where the sign matters), each model's AOC session decides among 41
candidate torques in [-2, 2] with the row's own observation and history (the controller's
decide, epsilon filter and hull v_hat as in a rollout). Printed per model: the share of rows
whose chosen torque has the logged (expert's) sign, and the same for the model's own head
l(b) (the argmax of ``predict`` over the candidates, no hull) and, for a ``--belief critic``
model, for the critic's own Q (its Q head on the same beliefs, config.json ``critic``).
docs/notes/belief.md uses the same measurement for the value belief with and without the dynamics
head. On the upright corpus the noiseless controller logs no torque at all (it starts exactly
upright), so ``--policy swingup-noise0.5 --sign-of expert`` takes the rows of a noisy
controller and the sign of the noiseless controller's torque at the row's state
(``aoc_cli.envs.pendulum_het.swingup_action``), with |that torque| > ``--min-torque``.

    python benchmarks/notes/belief_sign.py --store bench/store --corpus pendulum-het-30000r-s0 \\
        --models default,dynamics,critic,reward --rows 300
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from aoc_cli.threads import wait_passively  # noqa: E402

wait_passively()  # OpenMP threads wait passively, as under the aoc command (aoc_cli/threads.py)

import aoc_cli  # noqa: E402
from aoc_cli.envs import swingup_action  # noqa: E402
from aoc_cli.store import Store  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--store", default="bench/store")
    p.add_argument("--corpus", default="pendulum-het-30000r-s0")
    p.add_argument("--models", default="default,dynamics,critic,reward")
    p.add_argument("--rows", type=int, default=300)
    p.add_argument("--min-torque", type=float, default=0.3)
    p.add_argument("--policy", default="swingup-noise0")
    p.add_argument("--sign-of", choices=("logged", "expert"), default="logged")
    args = p.parse_args()
    corpus = Store.open(args.store).corpus(args.corpus)
    sys_codes, sys_labels = corpus.tag("system")
    pol_codes, pol_labels = corpus.tag("policy")
    expert = (sys_codes == sys_labels.index("normal")) & \
        (pol_codes == pol_labels.index(args.policy))
    rows = np.flatnonzero(expert)[:args.rows]
    if args.sign_of == "expert":
        acts = swingup_action(corpus.observations[rows], "normal").reshape(len(rows))
    else:
        acts = corpus.actions[rows][:, 0]
    keep = np.abs(acts) > args.min_torque
    rows, sign = rows[keep], np.sign(acts[keep])
    cand = np.linspace(-2, 2, 41, dtype=np.float32)[:, None]
    for m in args.models.split(","):
        # the paper's settings (pendulum-het sets none of its own), the public entry
        s = aoc_cli.open_session(args.corpus, store=args.store, model=m)
        hist_len = s.model.history_length
        hull, head, q_sign = [], [], []
        q_head = s.model.meta.get("critic", {}).get("q_head")
        for r, want in zip(rows, sign):
            h = corpus.history([r], hist_len)
            obs = corpus.observations[r]
            d = s.controller.decide(obs, h, candidates=cand)
            hull.append(np.sign(d.action[0]) == want)
            v = s.model.predict(obs[None], cand, h)
            head.append(np.sign(cand[int(np.argmax(v)), 0]) == want)
            if q_head is not None:
                q = s.model.beliefs(obs[None].repeat(len(cand), 0), cand, h) \
                    @ np.asarray(q_head["weight"])
                q_sign.append(np.sign(cand[int(np.argmax(q)), 0]) == want)
        print(json.dumps({"model": m, "belief": s.model.config.belief, "rows": len(rows),
                          "hull_sign_share": round(float(np.mean(hull)), 3),
                          "head_sign_share": round(float(np.mean(head)), 3),
                          "q_sign_share": round(float(np.mean(q_sign)), 3) if q_sign else None}),
              flush=True)


if __name__ == "__main__":
    main()
