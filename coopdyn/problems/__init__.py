"""Reference problems shared by tests, examples and benchmarks: the book's linear system (with
its exact solution) and arms facing each other around a box."""

from .facing_arms import PLACEMENT, facing_arms, object_start
from .linear_book import (
    BookParameters,
    BookSolution,
    Drive,
    Segment,
    book_positions,
    book_task,
    drives_controller,
    linear_book,
    linear_book_exact,
)

__all__ = [
    "PLACEMENT",
    "BookParameters",
    "BookSolution",
    "Drive",
    "Segment",
    "book_positions",
    "book_task",
    "drives_controller",
    "facing_arms",
    "linear_book",
    "linear_book_exact",
    "object_start",
]
