"""The RadarNeXt family (arXiv 2501.02314): net, necks, CenterHead, variants, targets, loss and paper numbers."""
