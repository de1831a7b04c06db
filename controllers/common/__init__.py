"""Machinery shared by the controller families: QP and horizon builders, design models."""
