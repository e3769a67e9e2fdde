"""The core: QP, Solution/Status, Solver and Problem bases, registry, evaluator, grading, scenes, expressions."""
