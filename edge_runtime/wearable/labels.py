"""The wearable classifier's classes (dissertation section 2.2.1), in model-output order."""
DISTRACTIONS = ("Phone", "Texting", "TouchScreen", "Drink", "Marker")
OTHER = "Other"
CLASSES = DISTRACTIONS + (OTHER,)
"""Phone, Texting, TouchScreen, Drink, Marker: the coupled manual distractions.
Other: non-coupled hand motions (scratching the face, touching an arm, shifting gear,
hand to knee) and the detector's false alarms; never alerted."""
