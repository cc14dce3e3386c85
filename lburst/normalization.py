"""The network's input normalisation: ImageNet's RGB mean and std (on 0..1).

Kept free of torch and of the rest of lburst: :func:`lburst.model.normalize_burst` applies it to
the network's input, and the noise models (:mod:`lburst.noise`) state ``gaussian-var:V`` noise
as a variance in that normalised space.
"""

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
