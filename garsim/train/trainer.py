"""Training loop for GarSim: AdamW + warmup/cosine schedule + gradient clipping, per-epoch validation in mm,
safetensors checkpoints with resume, tqdm progress, CSV log, seeded determinism, a NaN guard, and DDP
(``torchrun --nproc_per_node=2 ...`` on CPU with gloo).

The collision term of Eq. 7 is switched on after the other losses converge (paper Sec. 5):
at ``collision_start_epoch`` (epochs completed) if set, or once the validation score (the checkpoint's: error plus
``COLLISION_MM_PER_PCT`` x collision %) has not improved by ``collision_min_delta`` (relative, against its value at
the last such improvement) for ``collision_patience`` epochs.
"""

from __future__ import annotations

import csv
import json
import math
import os
import random
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
from safetensors.torch import load_file, save_file
from torch.utils.data import DataLoader, Dataset

from garsim.atomic import atomic_write
from garsim.data.sample import Sample
from garsim.geometry.cache import content_key
from garsim.model.baselines import MODELS
from garsim.model.config import GarSimConfig, check_known_keys
from garsim.model.garsim import GraphModel
from garsim.model.graph import GarmentGraph, build_graph, collate
from garsim.train.losses import LossWeights, collision_fraction, garsim_loss, per_graph_error_mm
from garsim.train.pairs import pair_ids, plan_batches, shard_indices

CSV_FIELDS = (
    "epoch",
    "step",
    "lr",
    "train_loss",
    "train_l2_mm",
    "val_err_mm",
    "val_prior_mm",
    "val_collision_pct",
    "val_score",
    "collision",
    "seconds",
)
COLLISION_MM_PER_PCT = 2.0
"""Checkpoint selection score = validation error (mm) + this x validation collision % (DeePSD's count):
one percent of vertices inside the body costs as much as 2 mm of mean error."""


class NonFiniteLossError(RuntimeError):
    """Raised when a loss becomes NaN/inf; the message names the offending samples."""


@dataclass
class TrainConfig:
    """Hyperparameters of a training run (saved as JSON in the run directory)."""

    out_dir: str = "runs/garsim"
    epochs: int = 50
    batch_size: int = 4
    lr: float = 1e-3
    min_lr_ratio: float = 0.05  # cosine decays to lr * min_lr_ratio
    warmup_steps: int = 50
    weight_decay: float = 1e-4
    grad_clip: float = 1.0
    seed: int = 0
    collision_start_epoch: int | None = None
    collision_patience: int = 3
    collision_min_delta: float = 0.01
    losses: LossWeights = field(default_factory=LossWeights)
    progress: bool = True
    resume: bool = True
    checkpoint_every: int = 1  # epochs
    max_steps_per_epoch: int | None = None  # for smoke tests
    threads: int = 1  # torch threads per process: more thrash (~30x slower) when the cores are shared
    device: str = "cpu"  # "cpu" (the documented path), "cuda", "cuda:N", or "auto" (CUDA when present)
    model: str = "garsim"  # a key of baselines.MODELS: "garsim", or "deepsd" (the DeePSD-style baseline)
    remesh_copies: int = 0  # remeshed variants per training sample (garsim.train.augment; `garsim train` applies it)
    mirror: bool = False  # also train on every sample mirrored left to right (garsim.train.augment.mirror_sample)
    # train only the parameters whose names start with one of these prefixes (e.g. "processor.film"), the rest
    # frozen; empty: all. A fine-tune of one pathway (the fabric's) that leaves what the model already knows alone
    trainable: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        self.trainable = tuple(self.trainable)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON dict."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrainConfig:
        """Inverse of ``to_dict``; unknown keys are an error."""
        check_known_keys(cls, d)
        d = dict(d)
        if isinstance(d.get("losses"), dict):
            d["losses"] = LossWeights(**d["losses"])
        return cls(**d)


class GraphDataset(Dataset):
    """Samples (a list, any sequence such as an on-disk store, or an iterable) -> cached GarmentGraphs."""

    def __init__(
        self,
        samples: Sequence[Sample] | Iterable[Sample],
        config: GarSimConfig,
        with_collision: bool = True,
        cache: bool = True,
        make_graph: Callable[..., GarmentGraph] = build_graph,
        pairs: bool = False,
    ):
        """``make_graph``: the model's graph builder (``GraphModel.make_graph``, ``build_graph``'s signature);
        ``pairs``: give every graph its paired-fabric group (``train.pairs.pair_ids``) as ``pair``; remeshed
        variants (``augment.RemeshAugmented``) are in none, mirror images (``augment.MirrorAugmented``) in groups
        of their own."""
        if not (hasattr(samples, "__len__") and hasattr(samples, "__getitem__")):
            samples = list(samples)
        if len(samples) == 0:
            raise ValueError("the dataset is empty: pass at least one Sample")
        self.samples = samples
        self.config = config
        self.with_collision = with_collision
        self.cache = cache
        self.make_graph = make_graph
        self.pair_ids = pair_ids(samples) if pairs else None
        self._graphs: dict[int, GarmentGraph] = {}
        self._tensors: dict[tuple, torch.Tensor] = {}  # the cached graphs' tensors by content (``_share``)

    def __len__(self) -> int:
        return len(self.samples)

    def build(self, indices: Iterable[int], desc: str | None = None) -> None:
        """Build and cache the graphs of ``indices`` not cached yet, in this order (a progress bar when ``desc``)."""
        todo = [int(i) for i in indices if int(i) not in self._graphs] if self.cache else []
        if desc is not None and todo:
            from tqdm.auto import tqdm

            todo = tqdm(todo, desc=desc, leave=False)
        for i in todo:
            self[i]

    def cached_indices(self) -> list[int]:
        """The indices whose graphs are cached, sorted."""
        return sorted(self._graphs)

    def cached_bytes(self, shared: bool = True) -> int:
        """Bytes of the cached graphs' tensors, each shared tensor counted once (``shared=False``: once per graph
        that holds it, as an unshared cache would)."""
        sizes = [(t.data_ptr(), t.element_size() * t.numel()) for g in self._graphs.values() for _, t in _tensors_of(g)]
        return sum(dict(sizes).values()) if shared else sum(size for _, size in sizes)

    def _share(self, g: GarmentGraph) -> GarmentGraph:
        """``g`` with each tensor replaced by an equal one of a graph cached before, where there is one: a sample's
        rest sample, its other target poses and its paired fabric copies have one template and canonical body, so
        most of their graphs' memory (encoder inputs, anchors, edges, faces) is the same (on v5 with the recipe's
        remeshed and mirrored variants, a third of the cache). Cached graphs are only read (a batch is a copy)."""
        for key, value in _tensors_of(g):
            kept = self._tensors.setdefault(content_key(value.numpy()), value)
            if kept is not value and torch.equal(kept, value):
                g[key] = kept
        return g

    def __getitem__(self, i: int) -> GarmentGraph:
        g = self._graphs.get(i)
        if g is None:
            s = self.samples[i]
            if s.target is None:
                raise ValueError(f"sample {i} ({s.meta.get('name', '')}) has no target: training needs ground truth")
            g = self.make_graph(
                s, self.config, with_collision=self.with_collision, name=str(s.meta.get("name") or f"sample{i}")
            )
            if self.pair_ids is not None:
                g.pair = torch.tensor([int(self.pair_ids[i])])
            if self.cache:
                self._graphs[i] = self._share(g)
        return g


def _tensors_of(g: GarmentGraph) -> list[tuple[str, torch.Tensor]]:
    """The (name, tensor) attributes of a graph (on the CPU, as built)."""
    return [(k, v) for k, v in g.items() if torch.is_tensor(v)]


def trainable_parameters(model: torch.nn.Module, prefixes: Sequence[str]) -> list[torch.nn.Parameter]:
    """The parameters whose names start with one of ``prefixes`` (all when empty); every other one is frozen
    (``requires_grad`` off). Raises ValueError when a prefix names no parameter."""
    named = list(model.named_parameters())
    if not prefixes:
        return [p for _, p in named]
    unknown = [pre for pre in prefixes if not any(name.startswith(pre) for name, _ in named)]
    if unknown:
        modules = sorted({name.split(".")[0] for name, _ in named})
        raise ValueError(f"trainable prefixes {unknown} name no parameter; the model's modules: {modules}")
    chosen = []
    for name, p in named:
        p.requires_grad_(any(name.startswith(pre) for pre in prefixes))
        if p.requires_grad:
            chosen.append(p)
    return chosen


def seed_everything(seed: int) -> None:
    """Seed Python, NumPy and torch; make torch deterministic."""
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True, warn_only=True)


def _dist_info() -> tuple[int, int]:
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def resolve_device(name: str) -> torch.device:
    """``TrainConfig.device`` -> a torch device: "auto" picks CUDA when present; absent CUDA is an error."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {name!r} asked for but CUDA is not available here; use --device cpu")
    if device.type not in ("cpu", "cuda"):
        raise ValueError(f"device must be cpu, cuda, cuda:N or auto, got {name!r}")
    return device


def init_distributed(device: torch.device | None = None) -> tuple[int, int]:
    """Join the process group when launched by torchrun (WORLD_SIZE > 1): gloo on CPU, NCCL on CUDA (one GPU
    per local rank). Returns (rank, world)."""
    if int(os.environ.get("WORLD_SIZE", "1")) > 1 and dist.is_available() and not dist.is_initialized():
        cuda = device is not None and device.type == "cuda"
        dist.init_process_group(backend="nccl" if cuda else "gloo")
    return _dist_info()


class Trainer:
    """Trains a GarSimModel (or another ``baselines.MODELS`` entry) on Samples; rank 0 writes checkpoints, the
    CSV log and the best model."""

    def __init__(
        self,
        model_config: GarSimConfig,
        train_config: TrainConfig,
        train_samples: Sequence[Sample] | Iterable[Sample],
        val_samples: Sequence[Sample] | Iterable[Sample] | None = None,
        init: GraphModel | None = None,
    ):
        """``init``: a trained model (same config) whose weights start the run; a checkpoint in
        ``out_dir`` still takes precedence when resuming."""
        self.cfg = train_config
        self.model_config = model_config
        torch.set_num_threads(max(1, train_config.threads))
        self.device = resolve_device(train_config.device)
        self.rank, self.world = init_distributed(self.device)
        if self.device.type == "cuda" and self.world > 1:
            self.device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
        seed_everything(train_config.seed)
        if train_config.model not in MODELS:
            raise ValueError(f"unknown model {train_config.model!r}; choose one of {sorted(MODELS)}")
        self.model = MODELS[train_config.model](model_config)
        if init is not None:
            if type(init) is not type(self.model):
                raise ValueError(f"init is a {type(init).__name__}, the run trains a {type(self.model).__name__}")
            if init.config != model_config:
                raise ValueError("init model has another config than model_config; pass init.config")
            self.model.load_state_dict(init.state_dict())
        self.model.to(self.device)
        make_graph = self.model.make_graph
        pairs = train_config.losses.pair > 0  # paired-fabric groups travel in one batch (garsim.train.pairs)
        self.train_set = GraphDataset(
            train_samples, model_config, with_collision=True, make_graph=make_graph, pairs=pairs
        )
        self.pair_ids = self.train_set.pair_ids
        # each process trains on a fixed shard of the samples (paired groups whole), so it builds and caches only
        # that shard's graphs; every process takes as many steps as the largest shard has batches
        groups = self.pair_ids if self.pair_ids is not None else np.full(len(self.train_set), -1)
        self._groups = groups
        shards = shard_indices(groups, self.world, train_config.seed)
        if any(len(s) == 0 for s in shards):
            raise ValueError(f"{len(groups)} training samples cannot feed {self.world} processes: use fewer")
        self.shard = shards[self.rank]
        rng = np.random.default_rng(0)  # the batch count depends on the group sizes only
        self._batches = max(len(plan_batches(groups[s], train_config.batch_size, rng)) for s in shards)
        self.val_set = (
            GraphDataset(val_samples, model_config, with_collision=True, make_graph=make_graph)
            if val_samples is not None
            else None
        )
        self.net: torch.nn.Module = self.model
        if self.world > 1:
            self.net = torch.nn.parallel.DistributedDataParallel(self.model)
        self.optimizer = torch.optim.AdamW(
            trainable_parameters(self.model, train_config.trainable),
            lr=train_config.lr,
            weight_decay=train_config.weight_decay,
            foreach=True,  # one op over all ~100 tensors (the CPU default loops over them): same steps, ~7% faster
        )
        self.out = Path(train_config.out_dir)
        self.epoch = 0
        self.step = 0
        self.collision_on = train_config.collision_start_epoch == 0
        self.best_val = math.inf
        self.plateau_epoch = -1  # the epoch of the last significant improvement (plateau detection)
        self.plateau_ref = math.inf  # the score then: an improvement counts when it beats this by min_delta
        self.history: list[dict[str, Any]] = []
        if self.rank == 0:
            self.out.mkdir(parents=True, exist_ok=True)
            (self.out / "train_config.json").write_text(json.dumps(train_config.to_dict(), indent=2))
        if train_config.resume and (self.out / "checkpoint" / "trainer_state.json").exists():
            self.load_checkpoint(self.out / "checkpoint")

    # -- schedule ---------------------------------------------------------------------------
    def _plan(self, epoch: int) -> list[list[int]]:
        """This process's batches of an epoch: its shard reshuffled, every paired-fabric group in one batch, cycled
        to the common step count."""
        rng = np.random.default_rng([self.cfg.seed, epoch, self.rank])
        local = plan_batches(self._groups[self.shard], self.cfg.batch_size, rng)
        mine = [[int(self.shard[i]) for i in batch] for batch in local]
        return [mine[i % len(mine)] for i in range(self._batches)]  # no shard is empty (__init__)

    def steps_per_epoch(self) -> int:
        """Optimizer steps per epoch on this rank."""
        steps = self._batches
        return min(steps, self.cfg.max_steps_per_epoch) if self.cfg.max_steps_per_epoch else steps

    def lr_at(self, step: int) -> float:
        """Linear warmup then cosine decay to lr * min_lr_ratio over all epochs."""
        total = max(1, self.cfg.epochs * self.steps_per_epoch())
        if step < self.cfg.warmup_steps:
            return self.cfg.lr * (step + 1) / self.cfg.warmup_steps
        t = min(1.0, (step - self.cfg.warmup_steps) / max(1, total - self.cfg.warmup_steps))
        lo = self.cfg.lr * self.cfg.min_lr_ratio
        return lo + 0.5 * (self.cfg.lr - lo) * (1.0 + math.cos(math.pi * t))

    # -- loops ------------------------------------------------------------------------------
    def _loader(self, epoch: int) -> DataLoader:
        return DataLoader(self.train_set, batch_sampler=self._plan(epoch), collate_fn=collate)

    def _check_finite(self, terms: dict[str, torch.Tensor], batch) -> None:
        bad = ~torch.isfinite(terms["total"].detach())
        flag = torch.tensor([float(bad.any())], device=self.device)
        if self.world > 1:
            dist.all_reduce(flag, op=dist.ReduceOp.MAX)
        if flag.item() > 0:
            names = [batch.name[i] for i in torch.nonzero(bad).ravel().tolist()] if bad.any() else []
            where = f"samples {names}" if names else "a sample on another rank"
            raise NonFiniteLossError(
                f"non-finite loss at epoch {self.epoch} step {self.step} (rank {self.rank}) on {where}; "
                f"terms: { {k: v.detach().tolist() for k, v in terms.items()} }"
            )

    def build_graphs(self) -> None:
        """Build this process's training graphs in index order before the first shuffled epoch: a sample, its rest
        sample, its paired fabrics and its remeshed variants are neighbours and share their canonical body's cached
        work (measured 2.2x faster than the shuffled order, 20 vs 46 ms a graph)."""
        show = self.cfg.progress and self.rank == 0
        self.train_set.build(np.sort(self.shard), desc="building graphs" if show else None)

    def train_epoch(self) -> dict[str, float]:
        """One pass over the training set; returns the mean loss and the mean of Eq. 3's L2 term in mm
        (``train_l2_mm``: 0.6 x the free and 0.4 x the pinned vertices' mean distance, so not comparable with the
        validation's plain mean error ``val_err_mm``)."""
        self.net.train()
        loader = self._loader(self.epoch)
        limit = self.steps_per_epoch()
        bar = None
        if self.cfg.progress and self.rank == 0:
            from tqdm.auto import tqdm

            bar = tqdm(total=limit, desc=f"epoch {self.epoch + 1}/{self.cfg.epochs}", leave=False)
        sums, count = {"loss": 0.0, "l2": 0.0}, 0
        for i, batch in enumerate(loader):
            if i >= limit:
                break
            lr = self.lr_at(self.step)
            for g in self.optimizer.param_groups:
                g["lr"] = lr
            batch = batch.to(self.device)
            pred, parts = self.net(batch, return_parts=True)
            loss, terms = garsim_loss(
                pred,
                batch,
                self.cfg.losses,
                use_collision=self.collision_on,
                direction=parts["direction"],
                magnitude=parts["magnitude"],
            )
            self._check_finite(terms, batch)
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if self.cfg.grad_clip > 0:
                torch.nn.utils.clip_grad_norm_(self.model.parameters(), self.cfg.grad_clip)
            self.optimizer.step()
            self.step += 1
            sums["loss"] += float(loss.detach())
            sums["l2"] += float(terms["l2"].detach().mean()) * 1000.0
            count += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(loss=f"{float(loss.detach()):.4g}", lr=f"{lr:.2e}")
        if bar is not None:
            bar.close()
        stats = torch.tensor([sums["loss"], sums["l2"], float(count)], dtype=torch.float64, device=self.device)
        if self.world > 1:
            dist.all_reduce(stats)
        n = max(stats[2].item(), 1.0)
        return {"train_loss": stats[0].item() / n, "train_l2_mm": stats[1].item() / n}

    @torch.no_grad()
    def validate(self) -> dict[str, float]:
        """Mean Euclidean error (mm) of the model and of the LBS prior, the model's collision % (nearest target-body
        vertex and its normal, DeePSD) and the checkpoint score on the validation set (all ranks)."""
        if self.val_set is None:
            nan = float("nan")
            return {"val_err_mm": nan, "val_prior_mm": nan, "val_collision_pct": nan, "val_score": nan}
        self.model.eval()
        idx = list(range(self.rank, len(self.val_set), self.world))
        sums = torch.zeros(4, dtype=torch.float64, device=self.device)
        with torch.no_grad():
            for start in range(0, len(idx), self.cfg.batch_size):
                batch = collate([self.val_set[i] for i in idx[start : start + self.cfg.batch_size]]).to(self.device)
                pred = self.model(batch)
                sums[0] += per_graph_error_mm(pred, batch.target, batch).sum().item()
                sums[1] += per_graph_error_mm(batch.prior, batch.target, batch).sum().item()
                sums[2] += 100.0 * collision_fraction(pred, batch).sum().item()
                sums[3] += batch.num_graphs
        if self.world > 1:
            dist.all_reduce(sums)
        n = max(sums[3].item(), 1.0)
        err, col = sums[0].item() / n, sums[2].item() / n
        return {
            "val_err_mm": err,
            "val_prior_mm": sums[1].item() / n,
            "val_collision_pct": col,
            "val_score": err + COLLISION_MM_PER_PCT * col,
        }

    def _update_collision_switch(self) -> None:
        if self.collision_on:
            return
        start = self.cfg.collision_start_epoch
        if start is not None:
            self.collision_on = self.epoch >= start
        elif self.plateau_epoch >= 0 and self.epoch - self.plateau_epoch >= self.cfg.collision_patience:
            self.collision_on = True

    def fit(self, stop_after_epoch: int | None = None) -> list[dict[str, Any]]:
        """Train for the configured epochs (continuing a resumed run); returns the per-epoch history.

        ``stop_after_epoch`` ends early (as an interruption would) without changing the schedule.
        """
        last = self.cfg.epochs if stop_after_epoch is None else min(self.cfg.epochs, stop_after_epoch)
        if self.epoch < last:
            self.build_graphs()
        while self.epoch < last:
            t0 = time.perf_counter()
            used = self.collision_on  # the collision term of this epoch (the log's column)
            train = self.train_epoch()
            val = self.validate()
            self.epoch += 1
            metric = val["val_score"] if math.isfinite(val["val_score"]) else train["train_l2_mm"]
            if self.plateau_epoch < 0 or metric < self.plateau_ref * (1.0 - self.cfg.collision_min_delta):
                self.plateau_epoch, self.plateau_ref = self.epoch, metric
            if metric < self.best_val:
                self.best_val = metric
                if self.rank == 0:
                    self.model.save(self.out / "best")
            self._update_collision_switch()
            row = {
                "epoch": self.epoch,
                "step": self.step,
                "lr": self.lr_at(self.step),
                **train,
                **val,
                "collision": int(used),
                "seconds": time.perf_counter() - t0,
            }
            self.history.append(row)
            if self.rank == 0:
                self._log(row)
                if self.epoch % self.cfg.checkpoint_every == 0 or self.epoch == last:
                    self.save_checkpoint(self.out / "checkpoint")
        if self.world > 1:
            dist.barrier()
        return self.history

    def _log(self, row: dict[str, Any]) -> None:
        path = self.out / "log.csv"
        new = not path.exists()
        with path.open("a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
            if new:
                w.writeheader()
            w.writerow({k: row[k] for k in CSV_FIELDS})

    # -- checkpoints ------------------------------------------------------------------------
    def save_checkpoint(self, directory: str | Path) -> Path:
        """Model (safetensors + config), optimizer tensors (safetensors), RNG and trainer state (JSON)."""
        d = Path(directory)
        self.model.save(d)
        opt = self.optimizer.state_dict()
        tensors: dict[str, torch.Tensor] = {}
        scalars: dict[str, Any] = {}
        for pid, st in opt["state"].items():
            for key, val in st.items():
                if torch.is_tensor(val):
                    tensors[f"state.{pid}.{key}"] = val.detach().contiguous().cpu()
                else:
                    scalars[f"state.{pid}.{key}"] = val
        tensors["rng.torch"] = torch.get_rng_state()
        atomic_write(d / "optimizer.safetensors", lambda p: save_file(tensors, str(p)))
        state = {
            "epoch": self.epoch,
            "step": self.step,
            "collision_on": self.collision_on,
            "best_val": self.best_val if math.isfinite(self.best_val) else None,
            "plateau_epoch": self.plateau_epoch,
            "plateau_ref": self.plateau_ref if math.isfinite(self.plateau_ref) else None,
            "param_groups": opt["param_groups"],
            "optimizer_scalars": scalars,
            "history": self.history,
            "train_config": self.cfg.to_dict(),
        }
        atomic_write(d / "trainer_state.json", lambda p: Path(p).write_text(json.dumps(state, indent=1)))
        return d

    def load_checkpoint(self, directory: str | Path) -> None:
        """Resume from ``save_checkpoint`` output (no pickle involved)."""
        d = Path(directory)
        state = json.loads((d / "trainer_state.json").read_text())
        loaded = type(self.model).load(d)
        if loaded.config != self.model_config:
            raise ValueError(
                f"checkpoint {d} was trained with another model config; use a new out_dir or the same config"
            )
        self.model.load_state_dict(loaded.state_dict())
        tensors = load_file(str(d / "optimizer.safetensors"), device=str(self.device))
        opt_state: dict[int, dict[str, Any]] = {}
        for key, val in tensors.items():
            if key.startswith("state."):
                _, pid, name = key.split(".", 2)
                opt_state.setdefault(int(pid), {})[name] = val
        for key, val in state.get("optimizer_scalars", {}).items():
            _, pid, name = key.split(".", 2)
            opt_state.setdefault(int(pid), {})[name] = val
        self.optimizer.load_state_dict({"state": opt_state, "param_groups": state["param_groups"]})
        if "rng.torch" in tensors:
            torch.set_rng_state(tensors["rng.torch"].cpu())
        self.epoch = int(state["epoch"])
        self.step = int(state["step"])
        self.collision_on = bool(state["collision_on"])
        self.best_val = math.inf if state["best_val"] is None else float(state["best_val"])
        # checkpoints before 2026-12-07 kept the plateau's epoch as best_epoch and no reference score: the best one
        self.plateau_epoch = int(state.get("plateau_epoch", state.get("best_epoch", -1)))
        ref = state.get("plateau_ref", state["best_val"])
        self.plateau_ref = math.inf if ref is None else float(ref)
        self.history = list(state.get("history", []))
