"""Ready-made scenes (re-exported from :mod:`coopdyn.problems`): the book's linear system and
identical arms facing each other around a box."""

from .problems.facing_arms import PLACEMENT, facing_arms, held_beam, object_start
from .problems.linear_book import book_positions, book_task, drives_controller, linear_book

__all__ = [
    "PLACEMENT",
    "book_positions",
    "book_task",
    "drives_controller",
    "facing_arms",
    "held_beam",
    "linear_book",
    "object_start",
]
