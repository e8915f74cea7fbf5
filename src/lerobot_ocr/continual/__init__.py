"""Continual learning (arXiv 2411.03294, Section V): collect OCR rollouts, merge, retrain, rebase."""
