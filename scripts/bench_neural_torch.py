#!/usr/bin/env python3
"""magcomp benchmark, PyTorch side: one training epoch of the same CNN (or LSTM) on the same
standardised windows that magcomp_bench_neural wrote (Debian's python3-torch, /usr/bin/python3).
Usage: bench_neural_torch.py DATA.bin THREADS [cnn|lstm [BATCH]]"""
import sys
import time

import numpy as np
import torch


class Cnn(torch.nn.Module):
    """The architecture of magcomp's CNN: two 1-D convolutions (16, 32 filters, kernel 5), each
    followed by ReLU and max pooling by 2, then 32 units and one output."""

    def __init__(self, features, window):
        super().__init__()
        self.conv1 = torch.nn.Conv1d(features, 16, 5, padding=2)
        self.conv2 = torch.nn.Conv1d(16, 32, 5, padding=2)
        self.fc1 = torch.nn.Linear(32 * (window // 4), 32)
        self.fc2 = torch.nn.Linear(32, 1)

    def forward(self, x):
        z = x.transpose(1, 2)
        z = torch.nn.functional.max_pool1d(torch.relu(self.conv1(z)), 2)
        z = torch.nn.functional.max_pool1d(torch.relu(self.conv2(z)), 2)
        return self.fc2(torch.relu(self.fc1(z.flatten(1)))).squeeze(1)


class Lstm(torch.nn.Module):
    """The architecture of magcomp's LSTM: two layers of 16 units over the window (batch first),
    the last step's output to one value."""

    def __init__(self, features):
        super().__init__()
        self.lstm = torch.nn.LSTM(features, 16, num_layers=2, batch_first=True)
        self.fc = torch.nn.Linear(16, 1)

    def forward(self, x):
        out, _ = self.lstm(x)
        return self.fc(out[:, -1]).squeeze(1)


def main():
    path, threads = sys.argv[1], int(sys.argv[2])
    arch = sys.argv[3] if len(sys.argv) > 3 else "cnn"
    torch.set_num_threads(threads)
    torch.manual_seed(1)
    with open(path, "rb") as f:
        n, nf, k, ne, batch = np.fromfile(f, dtype=np.int64, count=5)
        x = torch.from_numpy(np.fromfile(f, dtype=np.float32, count=n * nf).reshape(n, nf))
        y = torch.from_numpy(np.fromfile(f, dtype=np.float32, count=n))
        first = torch.from_numpy(np.fromfile(f, dtype=np.int64, count=n))
        ends = torch.from_numpy(np.fromfile(f, dtype=np.int64, count=ne))
    if len(sys.argv) > 4:
        batch = int(sys.argv[4])
    net = Cnn(int(nf), int(k)) if arch == "cnn" else Lstm(int(nf))
    opt = torch.optim.Adam(net.parameters(), lr=1e-3, weight_decay=5e-3)
    offsets = torch.arange(-(k - 1), 1, dtype=torch.int64)
    t0 = time.perf_counter()
    order = ends[torch.randperm(len(ends))]
    for s in range(0, len(order), int(batch)):
        e = order[s:s + int(batch)]
        rows = torch.maximum(e.unsqueeze(1) + offsets.unsqueeze(0), first[e].unsqueeze(1))
        xb = x.index_select(0, rows.flatten()).view(len(e), int(k), int(nf))
        loss = torch.nn.functional.mse_loss(net(xb), y[e])
        opt.zero_grad()
        loss.backward()
        opt.step()
    dt = time.perf_counter() - t0
    print(f"pytorch {arch}_epoch windows {len(ends)} features {nf} window {k} batch {batch} "
          f"threads {threads} seconds {dt:.2f} torch {torch.__version__}")


if __name__ == "__main__":
    main()
