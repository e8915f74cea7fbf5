"""Scripted experts that make demonstration datasets (import the task module you need)."""
