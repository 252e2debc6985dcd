"""One render, start to finish: prepare, plan, schedule the passes (threads or Dask), film, output, denoise. May import every room; nothing in core/ imports it."""
