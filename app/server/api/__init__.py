"""HTTP and WebSocket API: thin routers over the controller."""
