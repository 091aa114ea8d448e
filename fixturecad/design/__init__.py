"""``fixturecad design``: a fixture for any catalogue combination (combination, layout, fixture)."""
