"""Metrics of metamorphic relations: SUT output agreement and image quality."""
