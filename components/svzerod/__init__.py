"""Blocks of SimVascular's svZeroDSolver as hemocircuit components (one block per module).

Each module cites the svZeroDSolver source file its equations come from
(src/model/*.cpp at commit c7b0ca09).  The importer (hemocircuit.svzerod) maps their JSON
blocks to these types; docs/svzerod.md lists the mapping.  The registry imports each
block's module alone.
"""
