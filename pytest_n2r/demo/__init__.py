"""Built-in procedural demo scenes with exact ground truth."""
