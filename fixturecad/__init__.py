"""fixturecad: touch-sensing reference fixtures from contact group theory."""
