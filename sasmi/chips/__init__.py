"""Real chips: the train/validation split by scene group, and image statistics measured without masks."""
