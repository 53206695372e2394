"""Scene fields: trainable radiance fields that a scene file stores and the renderer queries."""
