"""Motion capture: the CMU data set and its file formats, views and scenes, basis and prior training,
the paper's experiments and the action example."""
