"""The DSFEC family (arXiv 2412.07411): net, heads, neck, variants, targets, loss and paper numbers."""
