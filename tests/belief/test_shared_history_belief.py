"""The control step's belief pass: one history's GRU summary broadcast to K candidates."""

from __future__ import annotations

import torch

from aoc_cli.belief.model import BeliefNet


def test_gru_once_gives_the_beliefs_of_the_repeated_history():
    torch.manual_seed(0)
    for history_length, use_action in ((4, True), (0, True), (3, False)):
        net = BeliefNet(3, 1, 1, history_length, hidden=32, belief_dim=20,
                        use_action=use_action).eval()
        k = 100
        obs = torch.randn(1, 3).expand(k, 3)
        act = torch.rand(k, 1) * 4 - 2
        steps = torch.randn(1, max(history_length, 1), 3 + 1 + 2) if history_length else None
        with torch.no_grad():
            repeated = net.belief(obs, act, None if steps is None else steps.expand(k, -1, -1))
            memory = None if steps is None else net.memory(steps).expand(k, -1)
            shared = net.belief_from_memory(memory, obs, act)
        assert shared.shape == (k, 20)
        # identical up to float32 rounding (the GRU's GEMM blocks by batch size)
        torch.testing.assert_close(shared, repeated, rtol=0, atol=1e-6)
        if use_action:  # the candidates' actions still move the belief
            assert (shared[0] - shared[1]).abs().max() > 1e-4
