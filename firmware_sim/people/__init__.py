"""Simulated people: the body model, motions and the chapter 4 worker."""
