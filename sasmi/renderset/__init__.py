"""Render sets on disk: written atomically and resumably by any number of processes (write), claims,
local processes each making a share, Dask clusters, shards, thread shares and contact sheets."""
