"""The Q-network: Q(image, gripper state, action) -> logit of P(grasp success).

Each column is a conv trunk over the image (plus coordinate planes), whose
flattened features and the gripper state form a per-state context vector; a
candidate action's embedding is added to that context and a small MLP (the
per-candidate head) maps it to one logit::

    ctx  = W_s [flatten(trunk(image)), state] + b_s           once per state
    h_1  = relu(ctx + W_a action)                             once per candidate
    h_j  = relu(W_j h_{j-1}),  logit = w_out . h_last

So maximising over many candidate actions (CEM) runs the trunk once per state
and only the cheap head once per candidate: ``encode`` then ``score``.

With ``NetConfig.pool="spatial"`` the context is a map instead of a vector
(QT-Opt's tile-and-add merge): the state and each candidate's action are
embedded, added at every position of the trunk's feature map (with coordinate
planes), passed through a 1x1 convolution, and max-pooled over positions
before the MLP.

A :class:`QNetwork` holds one or more columns.  With one column it is a plain
network.  With k > 1 it is a Progressive Neural Network (Rusu et al. 2016):
columns 0..k-2 are frozen, and every layer of column k-1 after the first
conv also reads the matching activations of the earlier columns through
lateral connections.  The output is the last column's; the earlier columns
compute exactly what they computed before.
"""

from __future__ import annotations

import copy
from collections import OrderedDict

import torch
from torch import nn

from .config import NetConfig

# A column's head: every layer after the conv trunk, including the laterals into it.  The order is the order in
# which ``new_head`` re-draws them (it fixes which random numbers each layer gets).
HEAD_PREFIXES = (
    "state_fc",
    "action_fc",
    "hidden_fcs",
    "out",
    "state_proj",
    "spatial_fc",
    "lateral.state",
    "lateral.hidden",
    "lateral.out",
)


IMAGENET_MEAN = torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1)
IMAGENET_STD = torch.tensor([0.229, 0.224, 0.225]).view(1, 3, 1, 1)


def resnet_trunk(name: str) -> nn.Sequential:
    """A torchvision ResNet without its pooling and classifier, its batch norms frozen (per sample, as CEM needs).

    Its parameter names are torchvision's (``conv1.weight``, ``layer1.0.bn1.running_mean``, ...), so an
    ImageNet state dict loads into it (learners/features.py).
    """
    import torchvision
    from torchvision.ops.misc import FrozenBatchNorm2d

    m = getattr(torchvision.models, name)(weights=None, norm_layer=FrozenBatchNorm2d)
    return nn.Sequential(
        OrderedDict(
            (k, getattr(m, k)) for k in ("conv1", "bn1", "relu", "maxpool", "layer1", "layer2", "layer3", "layer4")
        )
    )


def coordinate_planes(n: int) -> torch.Tensor:
    """(1, 2, n, n): x and y in [-1, 1] over an n x n grid (CoordConv's extra channels)."""
    ramp = torch.linspace(-1.0, 1.0, n)
    return torch.stack([ramp.view(1, n).expand(n, n), ramp.view(n, 1).expand(n, n)]).unsqueeze(0)


class QColumn(nn.Module):
    """One column: conv trunk, per-state context, per-candidate head, laterals from ``n_lateral`` earlier columns."""

    coords: torch.Tensor  # a buffer, registered with pool "spatial"

    def __init__(self, cfg: NetConfig, n_lateral: int = 0):
        super().__init__()
        self.n_lateral = n_lateral
        c_in = 3 + (2 if cfg.coord_channels else 0)
        self.encoder: nn.Module | None = resnet_trunk(cfg.encoder) if cfg.encoder != "conv" else None
        self.convs = nn.ModuleList()
        self.norms = nn.ModuleList()
        lateral: dict[str, nn.ModuleList] = {}
        for i, (c, s) in enumerate(zip(cfg.conv_channels, cfg.conv_strides) if self.encoder is None else ()):
            self.convs.append(nn.Conv2d(c_in, c, 3, s, 1))
            self.norms.append(nn.GroupNorm(min(8, c), c) if cfg.norm == "group" else nn.Identity())
            if i > 0 and n_lateral:
                lateral[f"conv{i}"] = nn.ModuleList(nn.Conv2d(c_in, c, 3, s, 1, bias=False) for _ in range(n_lateral))
            c_in = c
        flat = cfg.feature_dim
        self.pool = cfg.pool
        h = cfg.hidden
        if cfg.pool == "spatial":
            # per position: W_f [features, coordinates] + W_s state (once per state), then + W_a action
            self.state_fc: nn.Module = nn.Conv2d(cfg.feature_channels + 2, h, 1)
            self.state_proj = nn.Linear(cfg.state_dim, h, bias=False)
            self.spatial_fc = nn.Conv2d(h, h, 1)
            self.register_buffer("coords", coordinate_planes(cfg.feature_size), persistent=False)
        else:
            self.state_fc = nn.Linear(flat + cfg.state_dim, h)
        self.action_fc = nn.Linear(len(cfg.action_dims), h, bias=False)
        self.hidden_fcs = nn.ModuleList(nn.Linear(h, h) for _ in range(cfg.head_layers - 1))
        self.out = nn.Linear(h, 1)
        if n_lateral:
            lateral["state"] = nn.ModuleList(nn.Linear(flat, h, bias=False) for _ in range(n_lateral))
            for j in range(cfg.head_layers - 1):
                lateral[f"hidden{j}"] = nn.ModuleList(nn.Linear(h, h, bias=False) for _ in range(n_lateral))
            lateral["out"] = nn.ModuleList(nn.Linear(h, 1, bias=False) for _ in range(n_lateral))
        self.lateral = nn.ModuleDict(lateral)

    def _lat(self, name: str, inputs: list[torch.Tensor]) -> torch.Tensor | int:
        if not self.n_lateral:
            return 0
        return sum(m(x) for m, x in zip(self.lateral[name], inputs))  # type: ignore[call-overload]  # torch stubs: ModuleDict item is Module

    def encode(self, x: torch.Tensor, state: torch.Tensor, prev: list[dict]) -> dict:
        """Per-state activations: ``convs`` (list), ``flat`` and the context ``ctx`` (B, hidden)."""
        acts = []
        if self.encoder is not None:  # the ResNet reads ImageNet-normalised colours; x is image - 0.5
            x = self.encoder((x + 0.5 - IMAGENET_MEAN.to(x.dtype)) / IMAGENET_STD.to(x.dtype))
            acts.append(x)
        for i, conv in enumerate(self.convs):
            y = conv(x)
            if i > 0 and self.n_lateral:
                y = y + self._lat(f"conv{i}", [p["convs"][i - 1] for p in prev])
            x = torch.relu(self.norms[i](y))
            acts.append(x)
        if self.pool == "spatial":
            fmap = torch.cat([x, self.coords.expand(x.shape[0], -1, -1, -1).to(x.dtype)], 1)
            ctx = self.state_fc(fmap) + self.state_proj(state)[:, :, None, None]
            return {"convs": acts, "flat": x, "ctx": ctx}
        flat = x.flatten(1) if self.pool == "flatten" else x.amax(dim=(2, 3))
        ctx = self.state_fc(torch.cat([flat, state], 1)) + self._lat("state", [p["flat"] for p in prev])
        return {"convs": acts, "flat": flat, "ctx": ctx}

    def score(self, cache: dict, actions: torch.Tensor, prev: list[list[torch.Tensor]]) -> tuple[torch.Tensor, list]:
        """Logits (B, N) for candidate ``actions`` (B, N, A), plus the head activations for later columns."""
        if self.pool == "spatial":
            b, n = actions.shape[:2]
            ctx = cache["ctx"]  # (B, H, h, w)
            z = torch.relu(ctx.unsqueeze(1) + self.action_fc(actions)[..., None, None])  # (B, N, H, h, w)
            z = torch.relu(self.spatial_fc(z.flatten(0, 1)))
            h = z.amax(dim=(2, 3)).view(b, n, -1)
        else:
            h = torch.relu(cache["ctx"].unsqueeze(1) + self.action_fc(actions))
        acts = [h]
        for j, fc in enumerate(self.hidden_fcs):
            h = torch.relu(fc(h) + self._lat(f"hidden{j}", [p[j] for p in prev]))
            acts.append(h)
        logit = self.out(h) + self._lat("out", [p[-1] for p in prev])
        return logit.squeeze(-1), acts


class QNetwork(nn.Module):
    """Q(image, state, action) as logits; one column, or a progressive network of several."""

    coords: torch.Tensor | None  # a buffer with coord_channels, else None

    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.cfg = cfg
        self.columns = nn.ModuleList(QColumn(cfg, n_lateral=k) for k in range(cfg.columns))
        for col in self.columns[:-1]:
            col.requires_grad_(False)
        n = cfg.image_size
        if cfg.coord_channels:
            self.register_buffer("coords", coordinate_planes(n), persistent=False)
        else:
            self.coords = None

    def input(self, image: torch.Tensor) -> torch.Tensor:
        """The trunk's input: ``image - 0.5`` and the coordinate planes, in the caller's memory format.

        It is written straight into one buffer (no concatenation, no layout copy). Under CPU autocast the
        buffer is the autocast dtype, so the convolutions do not cast it again; the values are those the
        cast would give. Networks that see the same images (the two target networks) can share it.
        """
        b, _, h, w = image.shape
        channels_last = not image.is_contiguous() and image.is_contiguous(memory_format=torch.channels_last)
        device = image.device.type
        dtype = torch.get_autocast_dtype(device) if torch.is_autocast_enabled(device) else image.dtype
        extra = 0 if self.coords is None else self.coords.shape[1]
        fmt = torch.channels_last if channels_last else torch.contiguous_format
        x = torch.empty((b, image.shape[1] + extra, h, w), dtype=dtype, memory_format=fmt, device=image.device)
        pixels = x[:, : image.shape[1]]
        if dtype == image.dtype:
            torch.sub(image, 0.5, out=pixels)
        else:
            pixels.copy_(image - 0.5)
        if self.coords is not None:
            x[:, image.shape[1] :] = self.coords
        return x

    def encode(self, image: torch.Tensor, state: torch.Tensor) -> list[dict]:
        """Per-state context for :meth:`score`; ``image`` is float (B, 3, H, W) in [0, 1]."""
        return self.encode_input(self.input(image), state)

    def encode_input(self, x: torch.Tensor, state: torch.Tensor) -> list[dict]:
        """:meth:`encode` from the trunk's input :meth:`input` made."""
        caches: list[dict] = []
        for col in self.columns:
            caches.append(col.encode(x, state, caches))  # type: ignore[operator]  # torch stubs: ModuleList item is Module
        return caches

    def score(self, caches: list[dict], actions: torch.Tensor) -> torch.Tensor:
        """Logits (B, N) of candidate ``actions`` (B, N, A) given the context of B states."""
        heads: list[list[torch.Tensor]] = []
        logit = None
        for col, cache in zip(self.columns, caches):
            logit, acts = col.score(cache, actions, heads)  # type: ignore[operator]  # torch stubs: ModuleList item is Module
            heads.append(acts)
        assert logit is not None  # a network has at least one column
        return logit

    def forward(self, image: torch.Tensor, state: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """Logits (B,) of one action (B, A) per state."""
        return self.score(self.encode(image, state), action.unsqueeze(1)).squeeze(1)

    def trainable_parameters(self) -> list[nn.Parameter]:
        return [p for p in self.parameters() if p.requires_grad]


def head_rank(name: str) -> int | None:
    """The index in HEAD_PREFIXES of the head layer a parameter or module belongs to; None for the trunk.

    ``name`` is relative to a column (``hidden_fcs.0.weight``) or to the network
    (``columns.1.hidden_fcs.0.weight``).
    """
    rest = name.split(".", 2)[2] if name.startswith("columns.") else name
    return next((i for i, p in enumerate(HEAD_PREFIXES) if rest == p or rest.startswith(p)), None)


def is_head_parameter(name: str) -> bool:
    """True for a parameter of a column's head (everything after the conv trunk)."""
    return head_rank(name) is not None


def freeze_trunk(net: QNetwork) -> None:
    """Stop training the last column's trunk (``new_head_frozen``): only its head learns."""
    for name, p in net.columns[-1].named_parameters():
        if not is_head_parameter(name):
            p.requires_grad_(False)


def reinit_head(net: QNetwork) -> None:
    """Re-initialise the last column's head (``new_head``): every layer :func:`is_head_parameter` names."""
    col = net.columns[-1]
    layers = [
        (rank, m)
        for name, m in col.named_modules()
        if hasattr(m, "reset_parameters") and (rank := head_rank(name)) is not None
    ]
    for _, m in sorted(layers, key=lambda item: item[0]):  # stable: a layer's parts keep their order
        m.reset_parameters()


@torch.no_grad()
def shrink_perturb(net: QNetwork, alpha: float, sigma: float, seed: int) -> None:
    """Shrink and perturb (Ash and Adams 2020): w <- alpha * w + sigma * w_init for every trainable parameter.

    ``w_init`` is a fresh initialisation of the same architecture drawn from ``seed`` (so the noise has each
    layer's own initial scale); frozen columns are left as they are.
    """
    gen_state = torch.get_rng_state()
    torch.manual_seed(seed)
    fresh = QNetwork(net.cfg)
    torch.set_rng_state(gen_state)
    for (name, p), (fresh_name, q) in zip(net.named_parameters(), fresh.named_parameters()):
        assert name == fresh_name, (name, fresh_name)
        if p.requires_grad:
            p.mul_(alpha).add_(q, alpha=sigma)


def grow_column(parent: QNetwork, copy_last: bool) -> QNetwork:
    """A progressive network: ``parent``'s columns, frozen, plus one new trainable column.

    With ``copy_last`` (FT+PNN) the new column starts as a copy of the
    parent's last column and its new lateral connections start at zero, so
    the grown network computes exactly the parent's function; otherwise (PNN)
    the new column and its laterals are freshly initialised.
    """
    cfg = NetConfig.from_dict({**parent.cfg.to_dict(), "columns": parent.cfg.columns + 1})
    net = QNetwork(cfg)
    with torch.no_grad():
        for old, new in zip(parent.columns, net.columns):
            new.load_state_dict(old.state_dict())
        if copy_last:
            new_col, src = net.columns[-1], parent.columns[-1]
            own = src.state_dict()
            for name, t in new_col.state_dict().items():
                if name in own:
                    t.copy_(own[name])
                elif name.startswith("lateral."):
                    t.zero_()
                else:
                    raise AssertionError(f"FT+PNN: no source for parameter {name}")
    for col in net.columns[:-1]:
        col.requires_grad_(False)
    return net


def clone_frozen(net: QNetwork) -> QNetwork:
    """A copy of ``net`` for use as a target network (no gradients)."""
    out = copy.deepcopy(net)
    out.requires_grad_(False)
    return out
