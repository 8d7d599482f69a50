"""Plain TD3 against TD3+BC as the offline critic of ``--belief critic`` (docs/notes/belief.md).

Trains the critic of aoc_cli/belief/critic.py on a pendulum-het corpus with the behaviour-
cloning weight 0 (plain TD3, as the paper's reference code) and 0.4 (TD3+BC, aoc's default),
and prints, every RECORD_EVERY steps, the target critic's mean Q on the validation rows' logged
actions and on the actor's actions, beside the rows' discounted return-to-go. Pendulum rewards
are <= 0, so any Q above 0 is overestimation for certain.

    python benchmarks/notes/critic_bc.py --rows 20000 --steps 3000 --history 0 --hidden 64
"""

from __future__ import annotations

import argparse
import json
import tempfile

from aoc_cli.threads import wait_passively  # noqa: E402

wait_passively()  # OpenMP threads wait passively, as under the aoc command (aoc_cli/threads.py)

import torch


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--rows", type=int, default=20_000)
    p.add_argument("--steps", type=int, default=3_000)
    p.add_argument("--history", type=int, default=0)
    p.add_argument("--hidden", type=int, default=64)
    p.add_argument("--weights", default="0,0.4")
    args = p.parse_args()
    torch.set_num_threads(1)

    import aoc_cli
    from aoc_cli.belief import BeliefConfig, prepare
    # internal: this note fits the critic alone, the part of training it studies
    from aoc_cli.belief.critic import fit_critic
    from aoc_cli.belief.inputs import encode_corpus
    from aoc_cli.belief.model import Encoder, Normalisation

    corpus = aoc_cli.collect("pendulum-het", "p", store=tempfile.mkdtemp(), steps=args.rows,
                             seed=0).corpus
    for w in (float(x) for x in args.weights.split(",")):
        config = BeliefConfig(belief="critic", history_length=args.history, hidden=args.hidden,
                              critic_steps=args.steps, critic_bc_weight=w, threads=1)
        data = prepare(corpus, config, "m", True)
        norm = Normalisation.fit(corpus.observations, corpus.actions, corpus.rewards, False,
                                 data.values)
        enc = Encoder(norm, False, None, torch.device("cpu"))
        inputs = encode_corpus(corpus, enc, args.history, True, torch.device("cpu"))
        va = torch.as_tensor(data.val_rows[:4000])

        def report(record):
            print(json.dumps({"bc_weight": w, "step": record["epoch"],
                              "val_td_loss": round(record["val_loss"], 4),
                              "q_logged_mean": round(record["val_q_mean"], 2)}), flush=True)

        fit = fit_critic(corpus, inputs, enc, config, data.train_rows, data.val_rows,
                         torch.device("cpu"), on_record=report)
        with torch.no_grad():
            o, a, h = inputs.batch(va)
            q_logged = fit.critic.first(o, a, h).numpy() * fit.reward_scale
            q_actor = fit.critic.first(o, fit.actor(o, h), h).numpy() * fit.reward_scale
        ret = data.values[data.val_rows[:4000]]
        print(json.dumps({"bc_weight": w, "steps": args.steps,
                          "return_to_go_mean": round(float(ret.mean()), 2),
                          "q_logged_mean": round(float(q_logged.mean()), 2),
                          "q_actor_mean": round(float(q_actor.mean()), 2),
                          "q_actor_max": round(float(q_actor.max()), 2),
                          "share_q_actor_above_0": round(float((q_actor > 0).mean()), 3)}),
              flush=True)


if __name__ == "__main__":
    main()
