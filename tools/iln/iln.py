#!/usr/bin/python3
"""ILN (dissertation Ch. 4, Eq. 4.3) in PyTorch: train and evaluate on densemap's simulated range
images. Offline only (Debian's python3-torch, CPU); densemap itself never imports torch.

Data: `densemap-upsample-eval --export DIR` (simulated: raw float32 range images + index.csv) and
`densemap-upsample-eval --real SCANS --export-real DIR` (real scans' full range images with their
beam table; trained self-supervised: every n-th beam (--real-reduce) in, all beams as target).
  train:    iln.py train  --data DIR[,DIR2] --test-seeds 101,102 --model model.pt [--minutes M]
            [--real-val 32-39] (real scans held out for validation; the test range of a real
            dataset must never be exported for training)
            [--input 16x1024,16x2048] [--target 64x1024,128x2048,64x2048]
            (several directories: one sensor field of view each; every input/target pair that
            a directory holds is trained on)
  evaluate: iln.py eval   --data DIR --test-seeds 101,102 --model model.pt
  export:   iln.py export --data DIR --model model.pt --out models/iln.pb [--golden FILE]
            (protobuf weights, schema idl/iln_weights.proto, for densemap's C++ inference; the
            golden file holds a test crop, queries and PyTorch's output for the C++ test)

The model predicts, for each query laser, softmax weights over the 4 input pixels around it and
returns the weighted sum of their ranges: an EDSR-style convolutional encoder, a local feature per
neighbour (its feature vector and the query's offset from it), one self-attention layer across
the 4 neighbours, a shared linear score. Missing returns (range 0) get no weight.
"""
import argparse
import csv
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import torch
from torch import nn

MAX_RANGE = 80.0  # ranges are divided by this for the network
PRIOR_MIN_WEIGHT = 1e-4  # the prior's floors (as in core/upsample/src/iln.cpp)
PRIOR_MIN_RANGE = 1e-3


def load_index(data, real_reduce=(4, 2)):
    """{(dir, scene, seed, pose): {(rows, cols): (array, beam elevations)}} over the
    comma-separated data directories (an item pairs only the grids of one directory: one field of
    view). A real scan (scene "real") also yields its every n-th beam grids (real_reduce)."""
    items = {}
    for directory in data.split(","):
        load_directory(directory, items, real_reduce)
    return items


def read_beams(path):
    """A beam table file (densemap-upsample-eval): one elevation per line, '#' comments."""
    with open(path) as f:
        values = [line.split("#")[0].strip() for line in f]
    return np.array([float(v) for v in values if v], dtype=np.float64)


def load_directory(data, items, real_reduce):
    with open(os.path.join(data, "index.csv")) as f:
        for row in csv.DictReader(f):
            rows, cols = int(row["rows"]), int(row["cols"])
            image = np.fromfile(os.path.join(data, row["file"]), dtype=np.float32)
            image = image.reshape(rows, cols)
            if row.get("beams"):
                elevations = read_beams(os.path.join(data, row["beams"]))
            else:
                elevations = np.linspace(float(row["top_deg"]), float(row["bottom_deg"]), rows)
            key = (data, row["scene"], int(row["seed"]), int(row["pose"]))
            grids = items.setdefault(key, {})
            grids[(rows, cols)] = (image, elevations)
            if row["scene"] == "real":
                for n in real_reduce:
                    kept = image[::n]
                    grids[(kept.shape[0], cols)] = (np.ascontiguousarray(kept), elevations[::n])


def query_grid(in_elevations, in_cols, out_elevations, out_cols):
    """Continuous (row, col) of every output pixel in the input grid (same field of view): an
    output beam's row lies between the input beams around its elevation, in proportion to
    elevation (as RangeLayout::pixelOf; rows past the edges are clamped by `neighbours`)."""
    r = np.interp(-np.asarray(out_elevations), -np.asarray(in_elevations),
                  np.arange(len(in_elevations), dtype=np.float64))
    r = torch.from_numpy(r.astype(np.float32))
    c = torch.arange(out_cols, dtype=torch.float32) * in_cols / out_cols
    rr, cc = torch.meshgrid(r, c, indexing="ij")
    return torch.stack([rr.reshape(-1), cc.reshape(-1)], dim=-1)


def neighbours(image, queries):
    """The 4 pixels around each query: ranges (B,Q,4), flat indices (Q,4), offsets (Q,4,2)."""
    _, h, w = image.shape
    row = queries[:, 0].clamp(0, h - 1)
    r0 = row.floor().clamp(max=h - 2).long()
    c_floor = queries[:, 1].floor()
    c0 = c_floor.long() % w
    rows = torch.stack([r0, r0, r0 + 1, r0 + 1], dim=-1)
    cols = torch.stack([c0, (c0 + 1) % w, c0, (c0 + 1) % w], dim=-1)
    d_row = (row - r0.float()).unsqueeze(-1)
    d_col = (queries[:, 1] - c_floor).unsqueeze(-1)
    offsets = torch.stack([
        torch.cat([d_row, d_col], -1), torch.cat([d_row, d_col - 1], -1),
        torch.cat([d_row - 1, d_col], -1), torch.cat([d_row - 1, d_col - 1], -1)], dim=1)
    flat = rows * w + cols
    ranges = image.reshape(image.shape[0], -1)[:, flat]
    return ranges, flat, offsets


def bilinear_weights(offsets):
    return (1 - offsets[..., 0].abs()) * (1 - offsets[..., 1].abs())


def bilinear(image, queries):
    ranges, _, offsets = neighbours(image, queries)
    weight = bilinear_weights(offsets).unsqueeze(0) * (ranges > 0)
    total = weight.sum(-1)
    return torch.where(total > 1e-9, (weight * ranges).sum(-1) / total.clamp(min=1e-9),
                       torch.zeros_like(total))


class ResBlock(nn.Module):
    def __init__(self, width):
        super().__init__()
        self.conv1 = nn.Conv2d(width, width, 3, padding=1)
        self.conv2 = nn.Conv2d(width, width, 3, padding=1)

    def forward(self, x):
        return x + self.conv2(torch.relu(self.conv1(x)))


class ILN(nn.Module):
    """prior: add log(bilinear weight) - log(range) to each neighbour's score, so that an
    untrained score (zero) is bilinear interpolation of inverse range, which is exact for planes
    seen across the beam gap, and the network learns corrections to it."""

    def __init__(self, width=16, blocks=2, dim=16, prior=True):
        super().__init__()
        self.prior = prior
        self.head = nn.Conv2d(1, width, 3, padding=1)
        self.body = nn.Sequential(*[ResBlock(width) for _ in range(blocks)])
        self.embed = nn.Linear(width + 2, dim)
        self.q = nn.Linear(dim, dim)
        self.k = nn.Linear(dim, dim)
        self.v = nn.Linear(dim, dim)
        self.score = nn.Linear(dim, 1)
        if prior:
            nn.init.zeros_(self.score.weight)
            nn.init.zeros_(self.score.bias)
        self.width, self.blocks, self.dim = width, blocks, dim

    def forward(self, image, queries):
        """image (B,H,W) in metres (0: no return); queries (Q,2) continuous (row, col)."""
        x = (image / MAX_RANGE).unsqueeze(1)
        f = self.head(x)
        f = f + self.body(f)
        b, c, h, w = f.shape
        ranges, flat, offsets = neighbours(image, queries)
        feats = f.reshape(b, c, h * w).transpose(1, 2)[:, flat]  # (B,Q,4,C)
        z = self.embed(torch.cat([feats, offsets.unsqueeze(0).expand(b, -1, -1, -1)], -1))
        attention = torch.softmax(self.q(z) @ self.k(z).transpose(-1, -2) / math.sqrt(self.dim), -1)
        z = z + attention @ self.v(z)
        score = self.score(z).squeeze(-1)
        bilinear_weight = bilinear_weights(offsets)
        if self.prior:
            score = (score + torch.log(bilinear_weight.clamp(min=PRIOR_MIN_WEIGHT))
                     - torch.log(ranges.clamp(min=PRIOR_MIN_RANGE)))
        # A neighbour takes part when it has a return and a non-zero bilinear weight (a query on
        # a pixel line does not reach across it), as in bilinear interpolation.
        usable = (ranges > 0) & (bilinear_weight > 0)
        score = score.masked_fill(~usable, -1e9)
        weight = torch.softmax(score, -1) * usable
        return (weight * ranges).sum(-1)


def pairs(items, seeds, real_val, split, src, dst):
    """(input, target, (target image, target elevations), queries) per item of `split`: "test"
    takes the simulated seeds in `seeds` and the real scans in `real_val`."""
    out = []
    for (_, scene, seed, pose), grids in sorted(items.items()):
        held_out = seed in (real_val if scene == "real" else seeds)
        if held_out != (split == "test") or src not in grids or dst not in grids:
            continue
        queries = query_grid(grids[src][1], src[1], grids[dst][1], dst[1])
        out.append((torch.from_numpy(grids[src][0]), torch.from_numpy(grids[dst][0]), grids[dst],
                    queries))
    return out


def voxel_iou(pred, truth, elevations, voxel=0.1):
    rows, cols = truth.shape
    elev = np.radians(np.asarray(elevations))[:, None]
    az = (2 * np.pi * np.arange(cols) / cols)[None, :]
    def keys(r):
        mask = r > 0
        x = (r * np.cos(elev) * np.cos(az))[mask]
        y = (r * np.cos(elev) * np.sin(az))[mask]
        zz = (r * np.sin(elev) * np.ones_like(az))[mask]
        k = np.floor(np.stack([x, y, zz], -1) / voxel).astype(np.int64) + (1 << 20)
        return np.unique((k[:, 0] << 42) | (k[:, 1] << 21) | k[:, 2])
    a, t = keys(pred), keys(truth)
    common = np.intersect1d(a, t).size
    return common / max(1, a.size + t.size - common)


def evaluate(model, test, dst):
    sums = {"iln": [0.0, 0.0], "bilinear": [0.0, 0.0]}
    with torch.no_grad():
        for image, target, (_, elevations), queries in test:
            for name in sums:
                out = (model(image[None], queries) if name == "iln" else bilinear(image[None], queries))
                pred = out.reshape(dst).numpy()
                t = target.numpy()
                both = (pred > 0) & (t > 0)
                sums[name][0] += np.abs(pred[both] - t[both]).mean()
                sums[name][1] += voxel_iou(pred, t, elevations)
    return {k: (v[0] / len(test), v[1] / len(test)) for k, v in sums.items()}


def augment(image, noise, dropout, generator):
    """A real sensor's input: Gaussian range noise (std `noise` m) on the returns, and a
    fraction `dropout` of the pixels with no return."""
    returns = image > 0
    noisy = image + noise * torch.randn(image.shape, generator=generator)
    noisy = torch.where(returns, noisy.clamp(min=PRIOR_MIN_RANGE), image)
    keep = torch.rand(image.shape, generator=generator) >= dropout
    return noisy * keep


def train_model(a, model, train):
    """L1 on range (Adam), cosine learning rate from --lr to --lr-final; each step takes one
    training (image, target grid) pair and --queries random query lasers of that grid.
    `train`: [(input, target, (target image, elevations), queries)] over every grid pair."""
    print(f"iln: {len(train)} training pairs, "
          f"{sum(p.numel() for p in model.parameters())} parameters", flush=True)
    opt = torch.optim.Adam(model.parameters(), lr=a.lr)
    generator = torch.Generator().manual_seed(a.seed)
    order = torch.randperm(len(train), generator=generator).tolist()
    budget = a.minutes * 60
    start, step, cursor, mean = time.time(), 0, 0, None
    while (elapsed := time.time() - start) < budget:
        progress = min(1.0, elapsed / budget)
        lr = a.lr_final + 0.5 * (a.lr - a.lr_final) * (1 + math.cos(math.pi * progress))
        for group in opt.param_groups:
            group["lr"] = lr
        if cursor == len(order):
            order = torch.randperm(len(train), generator=generator).tolist()
            cursor = 0
        image, target, _, queries = train[order[cursor]]
        cursor += 1
        pick = torch.randperm(len(queries), generator=generator)[:a.queries]
        if a.noise > 0 or a.dropout > 0:
            image = augment(image, a.noise, a.dropout, generator)
        pred = model(image[None], queries[pick])[0]
        targets = target.reshape(-1)[pick]
        mask = (targets > 0) & (pred > 0)
        loss = (pred[mask] - targets[mask]).abs().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        step += 1
        mean = loss.item() if mean is None else 0.98 * mean + 0.02 * loss.item()
        if step % 100 == 0:
            print(f"iln: step {step}, {elapsed:.0f} s, lr {lr:.2e}, L1 {mean:.3f} m", flush=True)
            torch.save(model.state_dict(), a.model)
    torch.save(model.state_dict(), a.model)
    print(f"iln: trained {step} steps in {time.time() - start:.0f} s -> {a.model}", flush=True)


def schema_module():
    """idl/iln_weights.proto compiled for Python with protoc into a temporary directory."""
    idl = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "idl")
    out = tempfile.mkdtemp(prefix="iln_proto_")
    subprocess.run(["protoc", f"--python_out={out}", f"--proto_path={idl}",
                    os.path.join(idl, "iln_weights.proto")], check=True)
    sys.path.insert(0, out)
    import iln_weights_pb2  # pylint: disable=import-outside-toplevel
    return iln_weights_pb2


def load_pb(path):
    """A weights file written by `export`: ({width, blocks, dim, prior, state}, provenance)."""
    pb = schema_module()
    message = pb.IlnModel()
    with open(path, "rb") as f:
        message.ParseFromString(f.read())
    state = {t.name: torch.tensor(list(t.data), dtype=torch.float32).reshape(list(t.shape))
             for t in message.tensors}
    return ({"width": message.width, "blocks": message.blocks, "dim": message.dim,
             "prior": message.prior, "state": state}, message.provenance)


def export(a, model, test):
    """Weights as an IlnModel protobuf; optionally a golden output on a crop of a test image."""
    pb = schema_module()
    message = pb.IlnModel(version=1, width=model.width, blocks=model.blocks, dim=model.dim,
                          prior="inverse_bilinear" if model.prior else "",
                          max_range_m=MAX_RANGE, input_rows=test[0][0].shape[0],
                          input_cols=test[0][0].shape[1], provenance=a.provenance)
    for name, value in model.state_dict().items():
        message.tensors.add(name=name, shape=list(value.shape),
                            data=value.detach().reshape(-1).tolist())
    with open(a.out, "wb") as f:
        f.write(message.SerializeToString())
    print(f"iln: wrote {a.out} ({os.path.getsize(a.out)} bytes)")
    if not a.golden:
        return
    # A 12 x 48 crop with missing returns punched in, queries anywhere in it (wrapping columns,
    # rows on and between the input rows, the edges).
    generator = torch.Generator().manual_seed(a.seed)
    crop = test[0][0][2:14, 100:148].clone()
    crop.view(-1)[torch.randperm(crop.numel(), generator=generator)[:40]] = 0
    rows, cols = crop.shape
    queries = torch.rand(300, 2, generator=generator) * torch.tensor([rows - 1.0, cols])
    queries = torch.cat([queries, torch.tensor([[0.0, 0.0], [rows - 1.0, cols - 0.25],
                                                [rows - 1.0, 0.0], [5.0, 47.9]])])
    with torch.no_grad():
        ranges = model(crop[None], queries)[0]
    golden = pb.IlnGolden(rows=rows, cols=cols, image=crop.reshape(-1).tolist(),
                          queries=queries.reshape(-1).tolist(), ranges=ranges.tolist())
    with open(a.golden, "wb") as f:
        f.write(golden.SerializeToString())
    print(f"iln: wrote {a.golden} ({len(ranges)} golden ranges)")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("command", choices=["train", "eval", "export"])
    p.add_argument("--data", required=True,
                   help="data directories, comma-separated (one field of view each)")
    p.add_argument("--test-seeds", default="101,102")
    p.add_argument("--real-val", default="",
                   help="real scans (dataset indices FIRST-LAST or a list) held out for validation")
    p.add_argument("--real-weight", type=int, default=1,
                   help="train: each real pair is drawn this many times as often as a simulated "
                   "one")
    p.add_argument("--real-reduce", default="4,2",
                   help="real scans: inputs keep every n-th beam, for each n listed")
    p.add_argument("--input", default="16x1024",
                   help="input grids, comma-separated (pairs where the data has both grids)")
    p.add_argument("--target", default="64x1024,128x2048",
                   help="target grids, comma-separated (training draws from all of them)")
    p.add_argument("--model", default="iln.pt")
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--lr", type=float, default=1e-4)
    p.add_argument("--lr-final", type=float, default=1e-6, help="cosine schedule's last rate")
    p.add_argument("--queries", type=int, default=16384, help="query lasers a training step")
    p.add_argument("--width", type=int, default=16, help="encoder channels")
    p.add_argument("--blocks", type=int, default=2, help="encoder residual blocks")
    p.add_argument("--dim", type=int, default=16, help="local feature width")
    p.add_argument("--prior", choices=["inverse_bilinear", "none"], default="inverse_bilinear",
                   help="score prior (see ILN)")
    p.add_argument("--init", help="train: start from this checkpoint (.pt) or weights file (.pb; "
                   "its architecture too)")
    p.add_argument("--noise", type=float, default=0.0,
                   help="train: Gaussian range noise added to the input returns, m")
    p.add_argument("--dropout", type=float, default=0.0,
                   help="train: fraction of input pixels turned into missing returns")
    p.add_argument("--out", default="models/iln.pb", help="export: weights file")
    p.add_argument("--golden", help="export: also write a golden-output file")
    p.add_argument("--provenance", default="", help="export: how the model was trained")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args()
    torch.manual_seed(a.seed)
    torch.set_num_threads(a.threads)
    sources = [tuple(int(v) for v in t.split("x")) for t in a.input.split(",")]
    targets = [tuple(int(v) for v in t.split("x")) for t in a.target.split(",")]
    seeds = {int(s) for s in a.test_seeds.split(",")}
    real_val = set()
    for part in filter(None, a.real_val.split(",")):
        first, _, last = part.partition("-")
        real_val.update(range(int(first), int(last or first) + 1))
    items = load_index(a.data, tuple(int(n) for n in a.real_reduce.split(",")))
    grid_pairs = [(src, dst) for src in sources for dst in targets]
    test = {g: pairs(items, seeds, real_val, "test", *g) for g in grid_pairs}
    test = {g: t for g, t in test.items() if t}
    if a.init and a.init.endswith(".pb"):
        init, provenance = load_pb(a.init)
        a.width, a.blocks, a.dim = init["width"], init["blocks"], init["dim"]
        a.prior = init["prior"] or "none"
        print(f"iln: starting from {a.init} ({provenance[:200]})", flush=True)
    model = ILN(a.width, a.blocks, a.dim, prior=a.prior == "inverse_bilinear")
    if a.command == "train":
        if a.init and a.init.endswith(".pb"):
            model.load_state_dict(init["state"])
        elif a.init:
            model.load_state_dict(torch.load(a.init))
        train = [pair for g in grid_pairs for pair in pairs(items, seeds, real_val, "train", *g)]
        real = [pair for g in grid_pairs
                for pair in pairs({k: v for k, v in items.items() if k[1] == "real"}, seeds,
                                  real_val, "train", *g)]
        train += real * (a.real_weight - 1)
        train_model(a, model, train)
    else:
        model.load_state_dict(torch.load(a.model))
    if a.command == "export":
        export(a, model, next(iter(test.values())))
        return
    for (src, dst), items_test in test.items():
        for name, (mae, iou) in evaluate(model, items_test, dst).items():
            print(f"iln: test {name:8s} {src[0]}x{src[1]} -> {dst[0]}x{dst[1]}  "
                  f"MAE {mae:.3f} m  IoU {iou:.3f}", flush=True)


if __name__ == "__main__":
    main()
