"""Scenario runners: the closed-loop HRC suite, head error, the GOLA experiment, the wearable cohort, the demo."""
