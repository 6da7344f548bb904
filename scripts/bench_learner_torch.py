#!/usr/bin/env python3
"""The learner's update in PyTorch, for `crossroads bench learner`.

The same network (dueling: an MLP trunk of Linear+ReLU, or with --conv
3x3 convolutions, stride 1 then 2, then one Linear over the maps and the
extra features; value and advantage heads, Q = V + A - mean A), the same update (double-DQN targets under
no_grad, Huber loss weighted by importance weights, global-norm gradient
clipping, RMSprop or Adam, target copy every period) and the same kind of
input (sparse grids of a few cars, batches built before timing), timed the
same way: rounds of at least --seconds each after a warm-up, the median
reported. Prints one JSON object.
"""

import argparse
import json
import statistics
import time

import torch
from torch import nn


class Dueling(nn.Module):
    def __init__(self, inputs, hidden, actions, conv=None):
        super().__init__()
        self.conv = conv
        if conv is None:
            layers, width = [], inputs
            for h in hidden:
                layers += [nn.Linear(width, h), nn.ReLU()]
                width = h
            self.trunk = nn.Sequential(*layers)
        else:
            # Channels, rows, cols of the grid and the extra values after it.
            c, rows, cols, self.extra = conv
            layers = []
            for i, out in enumerate(hidden[:-1]):
                stride = 1 if i == 0 else 2
                layers += [nn.Conv2d(c, out, 3, stride=stride, padding=1), nn.ReLU()]
                c = out
                rows, cols = (rows - 1) // stride + 1, (cols - 1) // stride + 1
            self.maps = nn.Sequential(*layers)
            self.fc = nn.Linear(c * rows * cols + self.extra, hidden[-1])
            width = hidden[-1]
        self.value = nn.Linear(width, 1)
        self.advantage = nn.Linear(width, actions)

    def features(self, x):
        if self.conv is None:
            return self.trunk(x)
        c, rows, cols, extra = self.conv
        grid = x[:, : c * rows * cols].reshape(-1, c, rows, cols)
        maps = self.maps(grid).flatten(1)
        if extra:
            maps = torch.cat([maps, x[:, c * rows * cols :]], dim=1)
        return torch.relu(self.fc(maps))

    def forward(self, x):
        h = self.features(x)
        a = self.advantage(h)
        return self.value(h) + a - a.mean(dim=1, keepdim=True)


def batch(n, inputs, actions, gen):
    def grids():
        x = torch.zeros(n, inputs)
        cells = torch.randint(0, inputs - 4, (n, 24), generator=gen)
        x.scatter_(1, cells, torch.rand(n, 24, generator=gen))
        x[:, -4:] = torch.rand(n, 4, generator=gen)
        return x

    k = torch.tensor([1, 2, 4, 8])[torch.randint(0, 4, (n,), generator=gen)]
    done = torch.rand(n, generator=gen) < 0.02
    return {
        "obs": grids(),
        "next_obs": grids(),
        "actions": torch.randint(0, actions, (n,), generator=gen),
        "rewards": torch.where(done, torch.ones(n), -0.01 * k.float()),
        "discounts": torch.where(done, torch.zeros(n), 0.99 ** k.float()),
        "weights": torch.ones(n),
    }


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--input", type=int, default=2344)
    p.add_argument("--hidden", default="256,256")
    p.add_argument("--conv", default="", help="C,ROWS,COLS,EXTRA: a conv trunk over that grid")
    p.add_argument("--actions", type=int, default=5)
    p.add_argument("--batch", default="64,256")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--seconds", type=float, default=2.0)
    p.add_argument("--optimizer", choices=["rmsprop", "adam"], default="rmsprop")
    p.add_argument("--lr", type=float, default=2.5e-4)
    p.add_argument("--rmsprop-decay", type=float, default=0.95)
    p.add_argument("--eps", type=float, default=0.01)
    p.add_argument("--adam-betas", default="0.9,0.999")
    p.add_argument("--max-grad-norm", type=float, default=10.0)
    p.add_argument("--huber-delta", type=float, default=1.0)
    p.add_argument("--target-period", type=int, default=2500)
    a = p.parse_args()

    torch.set_num_threads(a.threads)
    torch.manual_seed(1)
    hidden = [int(h) for h in a.hidden.split(",")]
    conv = tuple(int(v) for v in a.conv.split(",")) if a.conv else None
    results = {}
    for size in [int(b) for b in a.batch.split(",")]:
        online = Dueling(a.input, hidden, a.actions, conv)
        target = Dueling(a.input, hidden, a.actions, conv)
        target.load_state_dict(online.state_dict())
        if a.optimizer == "rmsprop":
            opt = torch.optim.RMSprop(
                online.parameters(), lr=a.lr, alpha=a.rmsprop_decay, eps=a.eps
            )
        else:
            b1, b2 = (float(x) for x in a.adam_betas.split(","))
            opt = torch.optim.Adam(online.parameters(), lr=a.lr, betas=(b1, b2), eps=a.eps)
        gen = torch.Generator().manual_seed(7)
        batches = [batch(size, a.input, a.actions, gen) for _ in range(8)]
        steps = 0

        def update(b):
            nonlocal steps
            with torch.no_grad():
                best = online(b["next_obs"]).argmax(dim=1, keepdim=True)
                next_q = target(b["next_obs"]).gather(1, best).squeeze(1)
                y = b["rewards"] + b["discounts"] * next_q
            q = online(b["obs"]).gather(1, b["actions"].unsqueeze(1)).squeeze(1)
            per_item = nn.functional.huber_loss(q, y, reduction="none", delta=a.huber_delta)
            loss = (per_item * b["weights"]).mean()
            loss_value = loss.item()
            opt.zero_grad()
            loss.backward()
            if a.max_grad_norm > 0:
                nn.utils.clip_grad_norm_(online.parameters(), a.max_grad_norm)
            opt.step()
            # New priorities, as the learner sends them.
            (y - q.detach()).abs().add(1e-6).tolist()
            steps += 1
            if steps % a.target_period == 0:
                target.load_state_dict(online.state_dict())
            return loss_value

        for b in batches[:4]:
            update(b)
        rates, i = [], 0
        for _ in range(max(1, a.rounds)):
            start, n = time.perf_counter(), 0
            while time.perf_counter() - start < a.seconds:
                update(batches[i % len(batches)])
                i += 1
                n += 1
            rates.append(n / (time.perf_counter() - start))
        results[str(size)] = {"updates_per_sec": statistics.median(rates), "rounds": rates}
    print(
        json.dumps(
            {
                "torch_version": torch.__version__,
                "threads": torch.get_num_threads(),
                "results": results,
            }
        )
    )


if __name__ == "__main__":
    main()
