"""state.pt round trip (models.training.resume), as every trainer resumes from it."""

from __future__ import annotations

import numpy as np
import torch

from models.training.resume import load_state, save_state


def make(seed: int):
    torch.manual_seed(seed)
    net = torch.nn.Linear(4, 3)
    opt = torch.optim.Adam(net.parameters(), lr=1e-2)
    return net, opt


def train_steps(net, opt, rng, n):
    for _ in range(n):
        x = torch.from_numpy(rng.normal(size=(8, 4)).astype(np.float32)) + torch.randn(8, 4)
        loss = net(x).pow(2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()


def test_resumed_run_continues_exactly_like_an_uninterrupted_one(tmp_path):
    net, opt = make(0)
    rng = np.random.default_rng(1)
    train_steps(net, opt, rng, 3)
    save_state(tmp_path / "state.pt", {"model": net, "opt": opt}, rng, step=3, best=0.5)
    assert not (tmp_path / "state.pt.tmp").exists()  # written to a temporary file, then renamed
    train_steps(net, opt, rng, 4)
    expected = net.weight.detach().clone()

    net2, opt2 = make(99)  # different weights, fresh optimiser, other random state
    rng2 = np.random.default_rng(7)
    torch.manual_seed(123)
    st = load_state(tmp_path / "state.pt", {"model": net2, "opt": opt2}, rng2)
    assert st["step"] == 3 and st["best"] == 0.5
    train_steps(net2, opt2, rng2, 4)
    assert torch.equal(net2.weight, expected)
