"""``vtr_localizer_node``: colour-constant stereo visual teach & repeat (paper: Paton et al., ICRA 2015)."""
