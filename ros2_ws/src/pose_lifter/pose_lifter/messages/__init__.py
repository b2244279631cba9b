"""Wire formats, no I/O: conversion between arrays and messages, CDR, detector adapters."""
