"""Reports: render committed results (rows) into Markdown and figures; each module registers one kind."""
