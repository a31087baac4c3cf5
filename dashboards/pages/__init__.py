"""The dashboard's pages, one module each: its router, what it shows and how it reads it."""
