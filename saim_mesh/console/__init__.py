"""The commander's console (docs/console.md section 2): model, web server, mesh feed."""
