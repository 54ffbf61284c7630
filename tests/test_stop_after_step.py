"""Ctrl-C and kill reach a training loop between steps: the first lets the step in progress finish (its
checkpoint is then a whole step's state, and a resumed run repeats the uninterrupted one: the GAN's case is in
``test_train_gan_resume.py``), a second stops at once, and signals the command ignores stay ignored."""

from __future__ import annotations

import os
import signal
from types import SimpleNamespace

import pytest
import torch

from train.runs import training_loop


class FakeTrainer:
    """Steps that send themselves ``signals`` SIGINTs at step ``at``, between the step's two halves."""

    def __init__(self, at: int, signals: int):
        self.iteration, self.at, self.signals = 0, at, signals
        self.halves: list[str] = []
        self.saved: list[int] = []

    def step(self) -> dict[str, float]:
        self.halves.append(f"{self.iteration + 1}a")
        if self.iteration + 1 == self.at:
            for _ in range(self.signals):
                os.kill(os.getpid(), signal.SIGINT)
        self.halves.append(f"{self.iteration + 1}b")
        self.iteration += 1
        return {"loss": 0.0}

    def save(self, path) -> None:
        self.saved.append(self.iteration)


def run_loop(trainer: FakeTrainer, tmp_path, iters: int = 5) -> None:
    run = SimpleNamespace(
        checkpoint_path=tmp_path / "checkpoint.safetensors",
        nonfinite_path=tmp_path / "nonfinite.safetensors",
        log=lambda record: None,
        has_checkpoint=lambda: False,
    )
    training_loop(
        trainer,
        run,
        iters=iters,
        desc="test",
        device=torch.device("cpu"),
        log_every=1,
        checkpoint_every=0,
        advice="",
        main=True,
    )


def test_one_interrupt_lets_the_step_finish_and_saves_after_it(tmp_path, capsys):
    trainer = FakeTrainer(at=3, signals=1)
    with pytest.raises(KeyboardInterrupt):
        run_loop(trainer, tmp_path)
    assert trainer.halves == ["1a", "1b", "2a", "2b", "3a", "3b"]
    assert trainer.saved == [3]
    assert "stopping after this step" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the command's handler is back


def test_a_second_interrupt_stops_at_once(tmp_path):
    trainer = FakeTrainer(at=2, signals=2)
    with pytest.raises(KeyboardInterrupt):
        run_loop(trainer, tmp_path)
    assert trainer.halves == ["1a", "1b", "2a"]
    assert trainer.saved == [1]


def test_an_ignored_interrupt_stays_ignored(tmp_path):
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # as a shell starts a background job
    try:
        trainer = FakeTrainer(at=2, signals=1)
        run_loop(trainer, tmp_path)
        assert trainer.iteration == 5 and trainer.saved == [5]
    finally:
        signal.signal(signal.SIGINT, previous)
