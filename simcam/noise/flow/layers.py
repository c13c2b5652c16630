"""Noise Flow bijective layers (Abdelhamed 2020, ch. 6.3; Kingma & Dhariwal, Glow, arXiv:1807.03039).

Every layer maps noise-side tensors ``h`` (float, NCHW, C = 4) to latent-side
tensors with ``to_latent(h, cond) -> (h', logdet)``, ``logdet`` of shape (B,)
(log |det dh'/dh| summed over C, H, W), and back with ``from_latent(h', cond) -> h``.
``cond`` is a :class:`Cond` (clean patch, ISO weights, camera index).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import require_extra

torch = require_extra("torch", "torch")
nn = torch.nn
F = torch.nn.functional


@dataclass
class Cond:
    """Conditioning of one batch.

    Attributes
    ----------
    clean : Tensor (B, 4, H, W)
        Clean packed patch, normalised raw (0..1).
    iso : Tensor (B,)
        ISO speed (float).
    iso_w : Tensor (B, K)
        Interpolation weights of ``iso`` over the model's ISO knots (rows sum to 1
        inside the trained range; the legacy published mode gives one-hot or zeros).
    camera : Tensor (B,) int64
        Camera index into the model's camera list.
    """

    clean: "torch.Tensor"
    iso: "torch.Tensor"
    iso_w: "torch.Tensor"
    camera: "torch.Tensor"


def iso_weights(iso, knots, *, legacy: bool = False):
    """Piecewise-linear interpolation weights in log-ISO over sorted ``knots``.

    Parameters
    ----------
    iso : Tensor (B,)
        ISO values (inside ``[knots[0], knots[-1]]``; outside they clamp to the end knot).
    knots : Tensor (K,)
        Sorted ISO knots of the per-ISO parameters.
    legacy : bool
        Reproduce the released Noise Flow code: one-hot on an exact knot match,
        all zeros otherwise (so ``exp(0) = 1`` is used for any other ISO).

    Returns
    -------
    Tensor (B, K)
        Weights; ``w @ params`` is the interpolated per-ISO parameter. Written
        with clamp/min only (exports to ONNX without boolean indexing).
    """
    if legacy:
        return (iso[:, None] == knots[None, :]).to(knots.dtype)
    t = torch.log(iso.to(knots.dtype))[:, None]
    lk = torch.log(knots)[None, :]
    if knots.shape[0] == 1:
        return torch.ones_like(t)
    big = torch.full_like(lk[:, :1], 1.0e6)
    prev = torch.cat([lk[:, :1] - big, lk[:, :-1]], dim=1)
    nxt = torch.cat([lk[:, 1:], lk[:, -1:] + big], dim=1)
    up = (t - prev) / (lk - prev)
    down = (nxt - t) / (nxt - lk)
    return torch.clamp(torch.minimum(up, down), 0.0, 1.0)


def _sum_chw(x):
    return x.flatten(1).sum(dim=1)


class _SignalDependent(nn.Module):
    """A per-pixel scale layer: noise -> latent divides by ``scale(cond)``, ``logdet = -sum log s``."""

    def scale(self, cond: Cond):  # pragma: no cover - defined by subclasses
        raise NotImplementedError

    def to_latent(self, h, cond):
        s = self.scale(cond)
        return h / s, -_sum_chw(torch.log(s))

    def from_latent(self, h, cond):
        return h * self.scale(cond)


class SignalDependentPublished(_SignalDependent):
    """Signal-dependent layer of the released model (scope ``model/sdn_gain``).

    ``psi = exp(cam_params[:, m])``, ``gamma = exp(gain_params(ISO) * psi2) * ISO``,
    ``beta1 = exp(b1 * psi0)``, ``beta2 = exp(b2 * psi1)``,
    ``s = sqrt(beta1 * clean / gamma + beta2)``; noise -> latent divides by ``s``.
    This is where ISO and camera enter the released model (the paper puts them in
    the gain layer instead). ``clean`` below 0 is treated as 0.
    """

    def __init__(self, n_cameras: int, n_isos: int):
        super().__init__()
        self.beta1 = nn.Parameter(torch.full((1,), -5.0))
        self.beta2 = nn.Parameter(torch.zeros(1))
        self.cam_params = nn.Parameter(torch.zeros(3, n_cameras))
        self.gain_params = nn.Parameter(torch.zeros(n_isos))

    def scale(self, cond: Cond):
        psi = torch.exp(self.cam_params.index_select(1, cond.camera))  # (3, B)
        g = cond.iso_w @ self.gain_params
        gamma = torch.exp(g * psi[2]) * cond.iso
        b1 = torch.exp(self.beta1 * psi[0]) / gamma
        b2 = torch.exp(self.beta2 * psi[1])
        var = b1[:, None, None, None] * torch.clamp(cond.clean, min=0.0) + b2[:, None, None, None]
        return torch.sqrt(var)


class SignalDependentNLF(_SignalDependent):
    """Signal-dependent layer of the paper (Abdelhamed 2020, eq. 6.10): ``s = sqrt(beta1 I + beta2)``.

    ``beta1 = exp(b1)``, ``beta2 = exp(b2)`` (initialised ``b1 = -5``, ``b2 = 0``).
    With ``per_iso=True`` (simcam's extension) ``b1``, ``b2`` are per camera and
    per ISO knot, interpolated in log-ISO, so the layer contains any NLF
    ``var = beta1(ISO, m) I + beta2(ISO, m)`` exactly.
    """

    def __init__(self, n_cameras: int, n_isos: int, per_iso: bool = False):
        super().__init__()
        shape = (n_cameras, n_isos) if per_iso else (1, 1)
        self.per_iso = per_iso
        self.b1 = nn.Parameter(torch.full(shape, -5.0))
        self.b2 = nn.Parameter(torch.zeros(shape))

    def scale(self, cond: Cond):
        if self.per_iso:
            b1 = (self.b1.index_select(0, cond.camera) * cond.iso_w).sum(1)
            b2 = (self.b2.index_select(0, cond.camera) * cond.iso_w).sum(1)
        else:
            b1 = self.b1.reshape(1).expand(cond.iso.shape[0])
            b2 = self.b2.reshape(1).expand(cond.iso.shape[0])
        var = torch.exp(b1)[:, None, None, None] * torch.clamp(cond.clean, min=0.0) + torch.exp(b2)[
            :, None, None, None
        ]
        return torch.sqrt(var)


class GainScalar(nn.Module):
    """Gain layer of the released model: one scalar ``gain_val`` (noise -> latent divides)."""

    def __init__(self):
        super().__init__()
        self.log_gain = nn.Parameter(torch.zeros(1))

    def to_latent(self, h, cond):
        d = h[0].numel()
        return h * torch.exp(-self.log_gain), (-d * self.log_gain).expand(h.shape[0])

    def from_latent(self, h, cond):
        return h * torch.exp(self.log_gain)


class GainIsoCamera(nn.Module):
    """Gain layer of the paper (Abdelhamed 2020, eq. 6.12-6.14): ``gamma = psi_m * exp(v(ISO)) * ISO``.

    ``v`` is per ISO knot (interpolated in log-ISO, initialised so ``exp(v) = 1/200``),
    ``psi_m = exp(log_psi[m])`` per camera. Noise -> latent divides by ``gamma``;
    ``logdet = -D log gamma``.
    """

    def __init__(self, n_cameras: int, n_isos: int):
        super().__init__()
        self.v = nn.Parameter(torch.full((n_isos,), -math.log(200.0)))
        self.log_psi = nn.Parameter(torch.zeros(n_cameras))

    def log_gamma(self, cond):
        return cond.iso_w @ self.v + self.log_psi.index_select(0, cond.camera) + torch.log(cond.iso)

    def to_latent(self, h, cond):
        lg = self.log_gamma(cond)
        return h * torch.exp(-lg)[:, None, None, None], -h[0].numel() * lg

    def from_latent(self, h, cond):
        return h * torch.exp(self.log_gamma(cond))[:, None, None, None]


# TF fill_triangular order for 4x4 with 6 free entries (see data/noiseflow/README.md).
_L_IDX = ((3, 1, 0), (5, 2, 0), (4, 2, 1), (2, 3, 0), (1, 3, 1), (0, 3, 2))  # (vec, row, col)
_U_IDX = ((0, 0, 1), (1, 0, 2), (2, 0, 3), (4, 1, 2), (5, 1, 3), (3, 2, 3))


class LUConv1x1(nn.Module):
    """Invertible 1x1 convolution in LU form (Glow sec. 3.2): ``A = P L U``.

    Row-vector convention of the released code: each pixel's channel vector
    ``h`` maps to ``h @ A`` (noise -> latent), ``logdet = H W sum(log_S)``.
    ``U`` has diagonal ``sign_S * exp(log_S)``. The inverse is computed in eager
    mode and frozen into a buffer by :meth:`freeze` for export (no ``inverse`` op).
    """

    def __init__(self, c: int = 4, seed: int = 0):
        super().__init__()
        assert c == 4, "the LU fill order is defined for 4 channels"
        g = torch.Generator().manual_seed(seed)
        q, _ = torch.linalg.qr(torch.randn(c, c, generator=g, dtype=torch.float64))
        p, lo, up = torch.linalg.lu(q)
        self.register_buffer("P", p.float())
        self.register_buffer("sign_S", torch.sign(torch.diagonal(up)).float())
        self.log_S = nn.Parameter(torch.log(torch.abs(torch.diagonal(up))).float())
        self.L_vec = nn.Parameter(torch.stack([lo[r, c_] for _, r, c_ in sorted(_L_IDX)]).float())
        self.U_vec = nn.Parameter(torch.stack([up[r, c_] for _, r, c_ in sorted(_U_IDX)]).float())
        self._frozen = None

    @staticmethod
    def _fill(vec, idx, diag):
        m = torch.diag(diag)
        rows = torch.tensor([r for _, r, _ in idx])
        cols = torch.tensor([c for _, _, c in idx])
        vals = vec[torch.tensor([v for v, _, _ in idx])]
        return m.index_put((rows, cols), vals)

    def matrix(self):
        """The 4x4 matrix ``A`` (row-vector convention)."""
        one = torch.ones_like(self.log_S)
        lower = self._fill(self.L_vec, _L_IDX, one)
        upper = self._fill(self.U_vec, _U_IDX, self.sign_S * torch.exp(self.log_S))
        return self.P @ lower @ upper

    def freeze(self, on: bool = True):
        """Precompute ``A`` and ``A^-1`` (float64 inverse) as constants, or drop them."""
        if not on:
            self._frozen = None
            return
        with torch.no_grad():
            a = self.matrix()
            self._frozen = (a.clone(), torch.linalg.inv(a.double()).to(a.dtype))

    def _mix(self, h, a):
        # row-vector h @ a per pixel == conv2d with weight a^T (exports as one Conv)
        return F.conv2d(h, a.t()[:, :, None, None])

    def to_latent(self, h, cond):
        a = self._frozen[0] if self._frozen is not None else self.matrix()
        ld = (h.shape[2] * h.shape[3]) * self.log_S.sum()
        return self._mix(h, a), ld.expand(h.shape[0])

    def from_latent(self, h, cond):
        if self._frozen is not None:
            ainv = self._frozen[1]
        else:
            ainv = torch.linalg.inv(self.matrix())
        return self._mix(h, ainv)


class CouplingNet(nn.Module):
    """Coupling network of the released model (width 4).

    3x3 conv (2 -> w, zero SAME pad) -> batch norm (no affine, eps 1e-4) -> ReLU ->
    1x1 conv -> batch norm -> ReLU -> edge padding (zero pad by 1 plus a channel
    that is 1 on the padded border) -> 3x3 VALID conv (w + 1 -> 4), output times
    ``exp(3 logs)`` (Glow's ``conv2d_zeros``; zero-initialised, so the coupling
    starts as the identity).
    """

    def __init__(self, c_in: int = 2, width: int = 4, c_out: int = 4):
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, width, 3, padding=1)
        self.bn1 = nn.BatchNorm2d(width, eps=1e-4, affine=False, momentum=0.1)
        self.conv2 = nn.Conv2d(width, width, 1)
        self.bn2 = nn.BatchNorm2d(width, eps=1e-4, affine=False, momentum=0.1)
        self.last = nn.Conv2d(width + 1, c_out, 3, padding=0)
        self.logs = nn.Parameter(torch.zeros(c_out))
        nn.init.zeros_(self.last.weight)
        nn.init.zeros_(self.last.bias)

    def forward(self, x):
        x = F.relu(self.bn1(self.conv1(x)))
        x = F.relu(self.bn2(self.conv2(x)))
        border = 1.0 - F.pad(torch.ones_like(x[:, :1]), (1, 1, 1, 1))
        x = torch.cat([F.pad(x, (1, 1, 1, 1)), border], dim=1)
        return self.last(x) * torch.exp(3.0 * self.logs)[None, :, None, None]


class AffineCoupling(nn.Module):
    """Affine coupling (RealNVP/Glow): ``h_b -> h_b * exp(ls) + shift`` from ``NN(h_a)``.

    ``h_a`` = channels 0:2 (unchanged), ``h_b`` = channels 2:4; ``(shift, r)`` are the
    network's output channels 0:2 and 2:4; ``ls = rescale * tanh(r)``;
    ``logdet = sum(ls)``.
    """

    def __init__(self, width: int = 4):
        super().__init__()
        self.nn = CouplingNet(2, width, 4)
        self.rescale = nn.Parameter(torch.ones(()))

    def _params(self, h_a):
        out = self.nn(h_a)
        return out[:, :2], self.rescale * torch.tanh(out[:, 2:])

    def to_latent(self, h, cond):
        h_a, h_b = h[:, :2], h[:, 2:]
        shift, ls = self._params(h_a)
        return torch.cat([h_a, h_b * torch.exp(ls) + shift], dim=1), _sum_chw(ls)

    def from_latent(self, h, cond):
        h_a, h_b = h[:, :2], h[:, 2:]
        shift, ls = self._params(h_a)
        return torch.cat([h_a, (h_b - shift) * torch.exp(-ls)], dim=1)
