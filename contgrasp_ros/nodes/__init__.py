"""One module per node; each has a Node subclass and a ``main()`` entry point."""
