"""Ready-made scenes (re-exported from :mod:`coopdyn.problems`): the book's linear system,
identical arms facing each other around a box or a strip, and two planar three-link arms
carrying a flexible beam."""

from .problems.facing_arms import PLACEMENT, facing_arms, held_beam, object_start
from .problems.linear_book import book_positions, book_task, drives_controller, linear_book
from .problems.planar import midspan_deflection, planar_arms_beam, planar_ik

__all__ = [
    "PLACEMENT",
    "book_positions",
    "book_task",
    "drives_controller",
    "facing_arms",
    "held_beam",
    "linear_book",
    "midspan_deflection",
    "object_start",
    "planar_arms_beam",
    "planar_ik",
]
