"""``sun_update_node``: sun direction and chunked normalized sun radiosity (paper §III-E)."""
