"""Tools that evaluate the runtime: site sequences played through a server and scored."""
