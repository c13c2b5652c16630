"""Loader for the authors' released Noise Flow weights (``noiseflow_weights.npz``).

The weights are CC BY-NC-SA 4.0: this loader exists so tests can prove that
:class:`~simcam.noise.flow.model.NoiseFlow` computes what the published model
computes. Never copy the weights, or anything exported or trained from them,
into the repository or a shipped file.

Mapping (``data/noiseflow/README.md``): layers [0] sdn, [1..4] (conv, coupling),
[5] gain, [6..9] (conv, coupling); coupling ``unc_i`` uses network
``real_nvp_conv_template`` (i = 1), ``_1`` .. ``_3`` (i = 2..4) and ``_4`` .. ``_7``
(i = 6..9) -- the order the model was trained in (the authors' sampler loads
them reversed, a bug). The released channel order (0,0), (0,1), (1,1), (1,0) is
folded into the first 1x1 convolution's permutation, so the model's public
interface uses simcam's order (0,0), (0,1), (1,0), (1,1).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import NoiseModelError, require_extra
from . import layers as L
from .model import FlowConfig, NoiseFlow

torch = require_extra("torch", "torch")

#: Released packed order as indices into simcam's PACK_OFFSETS order.
RELEASED_TO_SIMCAM = (0, 1, 3, 2)
CAMERAS = ["IP", "GP", "S6", "N6", "G4"]
ISOS = [100.0, 400.0, 800.0, 1600.0, 3200.0]
_NETS = {1: "", 2: "_1", 3: "_2", 4: "_3", 6: "_4", 7: "_5", 8: "_6", 9: "_7"}


def load_published(path, *, legacy_iso: bool = False, dtype=None) -> NoiseFlow:
    """Build the released Noise Flow from ``noiseflow_weights.npz``.

    Parameters
    ----------
    path : path-like
        The ``.npz`` of checkpoint variables keyed by their TF names.
    legacy_iso : bool
        Reproduce the released ISO lookup (any ISO but the five knots gets factor 1);
        default interpolates in log-ISO inside 100..3200.
    dtype : torch.dtype, optional
        Parameter dtype (float32 default).

    Returns
    -------
    NoiseFlow
        In eval mode (batch norm uses the stored moving statistics).

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> path = tempfile.mkdtemp() + "/not_the_weights.npz"
    >>> np.savez(path, x=np.zeros(1))
    >>> load_published(path)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    simcam.errors.NoiseModelError: ...: variable 'model/sdn_gain/beta1' missing (expected the released checkpoint)
    """
    path = Path(path)
    try:
        w = dict(np.load(path))
    except (OSError, ValueError) as exc:
        raise NoiseModelError(f"{path}: cannot read published weights ({exc})") from None
    cfg = FlowConfig(arch="published", cameras=CAMERAS, iso_knots=ISOS, legacy_iso=legacy_iso)
    flow = NoiseFlow(cfg)

    def get(key):
        if key not in w:
            raise NoiseModelError(f"{path}: variable {key!r} missing (expected the released checkpoint)")
        return torch.from_numpy(np.asarray(w[key], dtype=np.float32))

    with torch.no_grad():
        sdn = flow.layers[0]
        sdn.beta1.copy_(get("model/sdn_gain/beta1"))
        sdn.beta2.copy_(get("model/sdn_gain/beta2"))
        sdn.cam_params.copy_(get("model/sdn_gain/cam_params"))
        sdn.gain_params.copy_(get("model/sdn_gain/gain_params"))
        flow.layers[9].log_gain.copy_(torch.log(get("model/sdn_gain/gain_val").double()).float())
        for i in (1, 2, 3, 4, 6, 7, 8, 9):
            pos = 2 * i - 1 if i < 5 else 2 * i - 2  # index in flow.layers of conv_i
            conv, coup = flow.layers[pos], flow.layers[pos + 1]
            assert isinstance(conv, L.LUConv1x1) and isinstance(coup, L.AffineCoupling)
            pre = f"level0/bijector{i}/Conv2d_1x1_{i}/"
            suf = f"_matpar_lu_conv2d_1x1_{i}_0"
            p = get(pre + "P" + suf)
            if i == 1:  # fold the released channel order into the first permutation
                q = torch.zeros(4, 4)
                for j, src in enumerate(RELEASED_TO_SIMCAM):
                    q[src, j] = 1.0
                p = q @ p
            conv.P.copy_(p)
            conv.L_vec.copy_(get(pre + "L_vec" + suf))
            conv.U_vec.copy_(get(pre + "U_vec" + suf))
            conv.log_S.copy_(get(pre + "log_S" + suf))
            conv.sign_S.copy_(get(pre + "sign_S" + suf))
            coup.rescale.copy_(get(f"level0/bijector{i}/rescaling_scale0").reshape(()))
            net = f"model/real_nvp_conv_template{_NETS[i]}/"
            nn_ = coup.nn
            nn_.conv1.weight.copy_(get(net + "l_1/W").permute(3, 2, 0, 1))
            nn_.conv1.bias.copy_(get(net + "l_1/b").reshape(-1))
            nn_.conv2.weight.copy_(get(net + "l_2/W").permute(3, 2, 0, 1))
            nn_.conv2.bias.copy_(get(net + "l_2/b").reshape(-1))
            nn_.last.weight.copy_(get(net + "l_last/W").permute(3, 2, 0, 1))
            nn_.last.bias.copy_(get(net + "l_last/b").reshape(-1))
            nn_.logs.copy_(get(net + "l_last/logs").reshape(-1))
            for k in (1, 2):
                bn = getattr(nn_, f"bn{k}")
                bn.running_mean.copy_(get(net + f"bn_nvp_conv_{k}/mean"))
                bn.running_var.copy_(get(net + f"bn_nvp_conv_{k}/var"))
    flow.eval()
    if dtype is not None:
        flow.to(dtype)
    return flow
