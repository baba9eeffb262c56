"""Re-export of :mod:`observer.closed_form` (the closed forms moved to the library, where
the scenarios declare them)."""

from observer.closed_form import ExactImpactOscillator, ball_position, closed_form_position  # noqa: F401
