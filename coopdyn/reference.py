"""Exact solution of the book's linear cooperative system (re-exported from
:mod:`coopdyn.problems.linear_book`)."""

from .problems.linear_book import BookParameters, BookSolution, Drive, Segment, linear_book_exact

__all__ = ["BookParameters", "BookSolution", "Drive", "Segment", "linear_book_exact"]
