"""The learner's Q-network in PyTorch, rebuilt from a weights file.

:func:`load_weights` reads a ``weights.safetensors`` (a file, a checkpoint
folder, a run's ``best/`` folder, or the bytes the learner's gRPC API
sends) and returns a :class:`QNetwork`: the dueling network of the file's
spec (an MLP trunk, or 3x3 convolutions and one fully connected layer),
whose ``state_dict`` keys are the file's tensor names. Its forward pass
takes a batch of flat float32 observations (the simulator's layout: the
channel-major grid, then the ego's features) and returns Q-values,
``Q = V + A - mean_a A``, as the Rust model computes them in fp32.

Needs the ``torch`` extra.
"""

from __future__ import annotations

from typing import Dict

import torch
from torch import nn

from .weights import NetworkSpec, Source, WeightsFile, read_weights

__all__ = ["QNetwork", "load_weights", "greedy"]


class QNetwork(nn.Module):
    """A dueling Q-network of ``spec`` (see :class:`crossroads.weights.NetworkSpec`),
    with PyTorch's default initialization until weights are loaded.

    Attributes: ``spec``, and ``version`` (the learner's version of the
    loaded weights; 0 for none).
    """

    def __init__(self, spec: NetworkSpec) -> None:
        super().__init__()
        spec.validate()
        self.spec = spec
        self.version = 0
        o = spec.observation
        layers: Dict[str, nn.Module] = {}
        if spec.trunk == "mlp":
            width = o.size
            for i, h in enumerate(spec.hidden):
                layers[str(i)] = nn.Linear(width, h)
                width = h
        else:
            c, rows, cols = o.channels, o.rows, o.cols
            for i, out in enumerate(spec.hidden[:-1]):
                stride = 1 if i == 0 else 2
                layers[str(i)] = nn.Conv2d(c, out, kernel_size=3, stride=stride, padding=1)
                c = out
                rows = (rows - 1) // stride + 1
                cols = (cols - 1) // stride + 1
            width = spec.hidden[-1]
            layers["fc"] = nn.Linear(c * rows * cols + o.extra, width)
        # ModuleDict keys give the file's names: trunk.0.weight, trunk.fc.bias.
        self.trunk = nn.ModuleDict(layers)
        self.value = nn.Linear(width, 1)
        self.advantage = nn.Linear(width, spec.num_actions)

    def features(self, obs: torch.Tensor) -> torch.Tensor:
        """The trunk's output for observations ``[batch, input_len]``."""
        if self.spec.trunk == "mlp":
            h = obs
            for layer in self.trunk.values():
                h = torch.relu(layer(h))
            return h
        o = self.spec.observation
        grid = obs[:, : o.grid_len].reshape(-1, o.channels, o.rows, o.cols)
        for name, layer in self.trunk.items():
            if name != "fc":
                grid = torch.relu(layer(grid))
        joined = grid.flatten(1)
        if o.extra > 0:
            joined = torch.cat([joined, obs[:, o.grid_len :]], dim=1)
        return torch.relu(self.trunk["fc"](joined))

    def streams(self, obs: torch.Tensor):
        """V(s) ``[batch, 1]`` and A(s, a) ``[batch, num_actions]``."""
        h = self.features(self._check(obs))
        return self.value(h), self.advantage(h)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Q-values ``[batch, num_actions]`` of observations ``[batch,
        input_len]`` (a single observation ``[input_len]`` gives
        ``[num_actions]``)."""
        single = obs.dim() == 1
        x = self._check(obs.unsqueeze(0) if single else obs)
        h = self.features(x)
        value = self.value(h)
        advantage = self.advantage(h)
        q = value + advantage - advantage.mean(dim=1, keepdim=True)
        return q[0] if single else q

    def _check(self, obs: torch.Tensor) -> torch.Tensor:
        n = self.spec.input_len
        if not isinstance(obs, torch.Tensor):
            raise TypeError(f"observations must be a torch.Tensor, got {type(obs).__name__}")
        if obs.dim() != 2 or obs.shape[1] != n:
            raise ValueError(
                f"observations must be [batch, {n}] ({self.spec.observation.kind} layout), "
                f"got {list(obs.shape)}"
            )
        if obs.dtype != torch.float32:
            raise ValueError(f"observations must be float32, got {obs.dtype}")
        return obs

    def load_weights_file(self, weights: WeightsFile) -> None:
        """Copies a file's tensors into this network; its spec must be this
        network's."""
        if weights.spec != self.spec:
            raise ValueError(f"the file's spec {weights.spec} is not this network's {self.spec}")
        state = {name: torch.from_numpy(t.copy()) for name, t in weights.tensors.items()}
        self.load_state_dict(state, strict=True)
        self.version = weights.version


def load_weights(source: Source, device: "torch.device | str | None" = None) -> QNetwork:
    """The network of a weights file (path, folder holding
    ``weights.safetensors``, or bytes), in eval mode, on ``device`` (the CPU
    by default). ``ValueError`` names what is wrong with a file that is not
    a crossroads weights file or does not fit its spec."""
    weights = read_weights(source)
    net = QNetwork(weights.spec)
    net.load_weights_file(weights)
    net.eval()
    if device is not None:
        net.to(device)
    return net


def greedy(q: torch.Tensor) -> torch.Tensor:
    """The greedy action of each row of Q-values (the first of equal
    maxima, as the Rust actors pick)."""
    return torch.argmax(q, dim=-1)
