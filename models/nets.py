"""The wearable classifiers of chapter 2 in one file: ConvLSTM, CNN and LSTM.

All three take the detector's capture after preprocessing
(``edge_runtime.wearable.classifier.preprocess``): a float32 tensor (N, 6, 33, 3) in
m/s^2 (6 subsequences x 33 frames x x/y/z) and return logits (N, n_classes). The
ConvLSTM also takes the first S of the 6 subsequences (N, S, 33, 3), the early
decision after S x 1.16 s of the capture (issue 12).
Softmax is applied by the caller (the ONNX graph appends it; see export/).

Reading of the dissertation's ConvLSTM (section 2.2.3, Figure 2.4/2.5)
-----------------------------------------------------------------------
Per subsequence: Conv1d(3->64, k3) -> ReLU -> Conv1d(64->64, k3) -> ReLU ->
dropout 0.5 -> max-pool; LSTM(100) over the 6 subsequences; dropout 0.4;
dense softmax(n_classes).

The text pools with size 2 and flattens to 896 features per subsequence
(64 x 14), which would give 412,398 parameters; the stated total is 79,598,
and that is reached exactly when the LSTM reads 64 features per subsequence:

    Conv 3*64*3 + 64          =    640
    Conv 64*64*3 + 64         = 12,352
    LSTM(64 -> 100), one bias = 66,000   (Keras counts 4*(100*(64+100) + 100))
    Dense 100*6 + 6           =    606
                                ------
                                79,598

So we build the network the parameter count describes: the max-pool spans the
whole subsequence (global max over time, 29 -> 1). PyTorch's ``nn.LSTM``
keeps two bias vectors (b_ih and b_hh) that only ever appear as a sum, so the
same network counts 79,998 parameters in PyTorch; :func:`keras_param_count`
gives the dissertation's count.

Inputs are divided by ``ACC_SCALE_MPS2`` (1 g) inside the network, so every
deployment feeds raw m/s^2.
"""
from __future__ import annotations

import torch
from torch import nn

ACC_SCALE_MPS2 = 9.80665
N_SUBSEQ, SUBSEQ_FRAMES, N_CHANNELS = 6, 33, 3


class ConvFeatures(nn.Module):
    """Conv1d(3->64,k3) -> ReLU -> Conv1d(64->64,k3) -> ReLU -> dropout, per subsequence."""

    def __init__(self, channels: int = 64, dropout: float = 0.5):
        super().__init__()
        self.conv = nn.Sequential(
            nn.Conv1d(N_CHANNELS, channels, 3),
            nn.ReLU(),
            nn.Conv1d(channels, channels, 3),
            nn.ReLU(),
            nn.Dropout(dropout),
        )
        self.channels = channels

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, S, F, C) -> (N, S, channels, F-4)."""
        n, s, f, c = x.shape
        y = self.conv(x.reshape(n * s, f, c).transpose(1, 2) / ACC_SCALE_MPS2)
        return y.reshape(n, s, self.channels, f - 4)


class ConvLSTM(nn.Module):
    """The dissertation's classifier: 79,598 parameters (Keras count) for 6 classes."""

    def __init__(self, n_classes: int = 6, channels: int = 64, hidden: int = 100):
        super().__init__()
        self.features = ConvFeatures(channels)
        self.lstm = nn.LSTM(channels, hidden, batch_first=True)
        self.dropout = nn.Dropout(0.4)
        self.head = nn.Linear(hidden, n_classes)

    def forward(self, x: torch.Tensor, all_steps: bool = False) -> torch.Tensor:
        """(N, S, 33, 3) -> logits (N, K) after the last of the S sub-windows (S = 6 is the whole
        capture; fewer is an early decision), or (N, S, K) after every step with ``all_steps``.
        The conv stack works on each sub-window alone and the LSTM is causal, so step s of
        ``all_steps`` is exactly the decision on the prefix ``x[:, :s]``."""
        f = self.features(x).amax(dim=3)  # global max-pool over time: (N, S, 64)
        out, (h, _) = self.lstm(f)
        return self.head(self.dropout(out if all_steps else h[-1]))

    def peeks(self, x: torch.Tensor, frames) -> torch.Tensor:
        """Logits (N, S, len(frames), K) of the decisions on partial sub-windows ("peeks"): for sub-window
        s and k of ``frames`` (each in 5..33), the first k frames of sub-window s and the state after the
        s - 1 complete ones. The conv is unpadded, so its first k - 4 outputs are exactly the conv of the
        truncated sub-window, and its features are their max; one LSTM step from the committed state reads
        them, and the state it leaves is not kept (the complete sub-window's step is the committed one)."""
        y = self.features(x)  # (N, S, C, 29)
        n, s = y.shape[:2]
        # the committed state before each sub-window: zeros, then the state after 1..S-1 (h and c)
        h0 = torch.zeros(1, n, self.lstm.hidden_size, dtype=y.dtype)
        hs, cs = [h0], [h0]
        h, c = h0, h0
        for t in range(s - 1):
            _, (h, c) = self.lstm(y[:, t:t + 1].amax(dim=3), (h, c))
            hs.append(h)
            cs.append(c)
        h_prev = torch.stack(hs, 2).reshape(1, n * s, -1)
        c_prev = torch.stack(cs, 2).reshape(1, n * s, -1)
        logits = []
        for k in frames:
            if not 5 <= k <= y.shape[3] + 4:
                raise ValueError(f"a peek needs 5..{y.shape[3] + 4} frames of a sub-window, got {k}")
            f = y[..., :k - 4].amax(dim=3).reshape(n * s, 1, -1)
            o, _ = self.lstm(f, (h_prev, c_prev))
            logits.append(self.head(self.dropout(o[:, 0])).reshape(n, s, -1))
        return torch.stack(logits, 2)


class CNN(nn.Module):
    """Baseline: the same conv stack, pooled per subsequence, then one dense softmax layer."""

    def __init__(self, n_classes: int = 6, channels: int = 64):
        super().__init__()
        self.features = ConvFeatures(channels)
        self.head = nn.Linear(N_SUBSEQ * channels, n_classes)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x).amax(dim=3).flatten(1))


class LSTM(nn.Module):
    """Baseline: LSTM(100) over the 198 raw frames, then dense softmax."""

    def __init__(self, n_classes: int = 6, hidden: int = 100):
        super().__init__()
        self.lstm = nn.LSTM(N_CHANNELS, hidden, batch_first=True)
        self.dropout = nn.Dropout(0.4)
        self.head = nn.Linear(hidden, n_classes)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        n = x.shape[0]
        _, (h, _) = self.lstm(x.reshape(n, -1, N_CHANNELS) / ACC_SCALE_MPS2)
        return self.head(self.dropout(h[-1]))


ARCHS = {"convlstm": ConvLSTM, "cnn": CNN, "lstm": LSTM}


def build(arch: str, n_classes: int) -> nn.Module:
    try:
        return ARCHS[arch](n_classes=n_classes)
    except KeyError:
        raise ValueError(f"unknown neural architecture {arch!r}; choose one of {sorted(ARCHS)}") from None


def torch_param_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def keras_param_count(model: nn.Module) -> int:
    """Parameters as Keras counts them: each LSTM layer has one bias vector, not two."""
    n = torch_param_count(model)
    for m in model.modules():
        if isinstance(m, nn.LSTM) and m.bias:
            n -= sum(getattr(m, f"bias_hh_l{k}").numel() for k in range(m.num_layers))
    return n
