"""Training, export and evaluation of evgate's motion-aware event suppression network."""
