"""The one-mode ring-downs of :mod:`independent.decays`, where the tests have long imported them."""

from independent.decays import forced_steady_state, free_decay, hilbert_backbone  # noqa: F401
