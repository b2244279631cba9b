"""Motion capture: the CMU loaders, views and scenes, prior training, experiments and the action example."""
