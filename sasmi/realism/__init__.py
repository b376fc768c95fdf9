"""Learning realism: `sasmi fit` (fit), renders laid on real floors (floors), `sasmi fit-scene` (fit_scene)."""
