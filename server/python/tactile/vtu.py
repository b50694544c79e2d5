"""A ParaView time series written from a Python loop, as `tactile-sim run` writes its own: each frame a VTU file
(Simulation.write_vtu), and a PVD collection that lists them with their simulated times (open the .pvd in
ParaView; meshio reads each .vtu)."""

from __future__ import annotations

import os
import pathlib
import xml.etree.ElementTree as ET
from collections.abc import Sequence

from tactile._core import Simulation


class VtuSeries:
    """Frames of a Simulation into `folder` (made if missing): ``write(sim)`` adds ``frame_NNNNNN.vtu`` with the
    `fields` named (those of Simulation.write_vtu: cauchy_stress, green_strain, von_mises, principal_stretches,
    contact_force) and rewrites ``series.pvd`` (`name`) at once, so that a loop stopped early leaves a series that
    opens.

        >>> series = VtuSeries("out", fields=["von_mises"])          # doctest: +SKIP
        >>> for _ in range(20):                                       # doctest: +SKIP
        ...     sim.advance(0.01)
        ...     series.write(sim)
    """

    def __init__(self, folder: str | os.PathLike[str], fields: Sequence[str] = (), name: str = "series.pvd") -> None:
        self.folder = pathlib.Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.fields = list(fields)
        self.pvd = self.folder / name
        self.frames: list[tuple[float, str]] = []  # (simulated time [s], file name)

    def write(self, sim: Simulation) -> pathlib.Path:
        """The body as it is now as the next frame, at sim.time; returns the frame's path."""
        file = f"frame_{len(self.frames):06d}.vtu"
        sim.write_vtu(str(self.folder / file), self.fields)
        self.frames.append((sim.time, file))
        root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
        collection = ET.SubElement(root, "Collection")
        for t, f in self.frames:
            ET.SubElement(collection, "DataSet", timestep=f"{t:.9g}", group="", part="0", name="body", file=f)
        tmp = self.pvd.with_name(f".{self.pvd.name}.tmp")
        ET.ElementTree(root).write(tmp, xml_declaration=True, encoding="utf-8")
        os.replace(tmp, self.pvd)
        return self.folder / file


__all__ = ["VtuSeries"]
