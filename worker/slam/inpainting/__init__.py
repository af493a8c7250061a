"""Background restoration (paper section 4.2): reference frames + PatchMatch for RGB and depth."""
