"""Shared test set-up: this folder is on sys.path, so tests import its helper modules."""
