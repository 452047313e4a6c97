"""Instrument files written here, byte by byte, after the layouts that independent open
readers document (not after pmdsim's or surfalize's readers), for the format tests of
``pmdsim.topofile`` (tests/config/test_topofile_formats.py):

- Sensofar ``.plu``: Gwyddion's ``modules/file/sensofar.c`` (GPL) and SurfaceTopography's
  ``IO/PLU.py`` (MIT, tested there on real instrument files): a 500-byte header (date,
  time, comment, the axes' calibration, the measurement configuration), then the grid's
  size (rows, columns: uint32) before the float32 heights in micrometres, row by row,
  1000001 for a point not measured, then their minimum and maximum.
- Keyence ``.vk4``: Gwyddion's ``modules/file/keyence.c`` and SurfaceTopography's
  ``IO/VK.py``: magic ``VK4_``, DLL version, four zero bytes, an offset table of 18
  uint32, the measurement conditions (x/y length per pixel and z length per digit in
  picometres), a height image (width, height, bit depth, compression, byte size, palette
  range, a 768-byte palette, then the unsigned integers row by row) and the character
  strings (UTF-16 title and lens name).
- Zygo ``.datx`` (HDF5): SurfaceTopography's ``IO/DATX.py`` and prysm's ``io.py``
  (MIT): a ``MetaData`` table of (Source, Link, Destination) strings leading from
  ``Root`` through ``Measurement`` and ``Surface`` to the surface's ``Path``; the surface
  dataset under ``/Data/Surface`` with the attributes ``Unit``, ``No Data`` and the
  compound ``X/Y/Z Converter`` (Category, BaseUnit, Parameters; the lateral spacing in
  metres is Parameters[1]); prysm also needs the surface's ``Wavelength`` (m),
  ``Interferometric Scale Factor`` and ``Obliquity Factor`` and an ``Attributes`` group
  (its last member's ``...Resolution:Value``, the lateral resolution in metres).

Each writer takes the heights as (rows along y, columns along x) in the unit the format
stores and the spacing; ``truncate``/garbling is done by the tests on the bytes.
"""

from __future__ import annotations

import struct

import numpy as np

PLU_NOT_MEASURED = 1000001.0


def write_plu(path, z_um, dx_um, dy_um, *, with_grid_size=True, measurement_type=3):
    """A Sensofar .plu file (the layout above). ``with_grid_size=False`` leaves out the
    grid's size before the heights (the layout surfalize 0.19.2 reads)."""
    z = np.asarray(z_um, "<f4")
    ny, nx = z.shape
    head = b"Tue Dec  1 12:00:00 2026".ljust(128, b"\0") + struct.pack("<I", 0) + bytes(256)
    # axes: yres, xres, N_tall; dy_multip, mppx, mppy, x_0, y_0, mpp_tall, z_0
    head += struct.pack("<3I7f", ny, nx, 1, 1.0, dx_um, dy_um, 0.0, 0.0, 1.0, 0.0)
    # measurement: type, algorithm, method, objective, area, xres_area, yres_area, xres,
    # yres, na; incr_z (double), range (float), n_planes, tpc_umbral_F; restore,
    # num_layers (1), version (0: 2000), config_hardware, num_images (0: no colour image
    # after the heights), reserved, 2 padding; factor_delmacio
    head += struct.pack("<10IdfII", measurement_type, 0, 0, 0, 3, nx, ny, nx, ny, 1, 0.1, 10.0,
                        1, 0)
    head += bytes([0, 1, 0, 0, 0, 0, 0, 0]) + struct.pack("<I", 0)
    assert len(head) == 500
    valid = z[z != PLU_NOT_MEASURED]
    body = (struct.pack("<II", ny, nx) if with_grid_size else b"") + z.tobytes()
    path.write_bytes(head + body + struct.pack("<ff", valid.min(), valid.max()))


def write_vk4(path, counts, dx_pm, dy_pm, dz_pm, *, bit_depth=32, version=4):
    """A Keyence .vk4 file (``version=3``: .vk3, whose offset table lacks the last, reserved
    entry): ``counts`` (rows, columns) unsigned integers, heights ``counts * dz_pm``
    picometres, spacing ``dx_pm``, ``dy_pm`` (integers, pm)."""
    dtype = {8: "<u1", 16: "<u2", 32: "<u4"}[bit_depth]
    counts = np.asarray(counts, dtype)
    ny, nx = counts.shape
    header = f"VK{version}_".encode() + bytes([0, 0, 0, 1]) + bytes(4)
    entries = 18 if version == 4 else 17
    conds_at = 12 + entries * 4
    conds = [0] * 76  # 304 bytes: the documented minimum
    conds[0] = 304
    conds[1:8] = [2026, 12, 1, 12, 0, 0, 60]  # year .. second, minutes from UTC
    conds[18] = 10  # optical zoom x 10
    conds[24] = 200  # lens magnification x 10
    conds[42:45] = [dx_pm, dy_pm, dz_pm]  # x, y length per pixel; z length per digit
    conds_bytes = struct.pack("<76I", *conds)
    height_at = conds_at + len(conds_bytes)
    image = struct.pack("<7I", nx, ny, bit_depth, 0, counts.nbytes, int(counts.min()),
                        int(counts.max())) + bytes(768) + counts.tobytes()
    strings_at = height_at + len(image)
    strings = b""
    for text in ("pmdsim test", "20x"):
        strings += struct.pack("<I", len(text)) + text.encode("utf-16-le")
    table = [0] * entries
    table[0] = conds_at  # setting (measurement conditions)
    table[6] = height_at  # height[0]
    table[16] = strings_at  # string data
    path.write_bytes(header + struct.pack(f"<{entries}I", *table) + conds_bytes + image + strings)


DATX_UNITS = {"NanoMeters": 1e-9, "MicroMeters": 1e-6, "MilliMeters": 1e-3, "Meters": 1.0}


def write_datx(path, z, dx_m, dy_m, *, unit="NanoMeters", no_data=None, metadata=True,
               z_category="HeightCat", lateral_category="LateralCat", unit_attr=None):
    """A Zygo .datx (HDF5) file: heights ``z`` (rows, columns) in ``unit``; ``no_data``
    the value marking points not measured (default: the largest float64)."""
    import h5py

    z = np.asarray(z, np.float64)
    no_data = np.finfo(np.float64).max if no_data is None else no_data
    surface = "{6A1B3C0E-0000-4000-8000-00000000002A}"
    measurement = "{6A1B3C0E-0000-4000-8000-000000000001}"
    conv = np.dtype([("Category", "S32"), ("BaseUnit", "S32"), ("Parameters", "<f8", (4,))])

    def converter(category, base, params):
        return np.array([(category.encode(), base.encode(), params)], conv)

    with h5py.File(path, "w") as h5:
        if metadata:
            rows = [("Root", "Measurement", measurement), (measurement, "Surface", surface),
                    (surface, "Path", f"/Data/Surface/{surface}")]
            table = np.dtype([("Source", "S64"), ("Link", "S64"), ("Destination", "S64")])
            h5["MetaData"] = np.array([tuple(s.encode() for s in r) for r in rows], table)
        ds = h5.create_dataset(f"Data/Surface/{surface}", data=z)
        ds.attrs["Unit"] = np.array([(unit_attr or unit).encode("utf-8")])
        ds.attrs["No Data"] = np.array([no_data], np.float64)
        ds.attrs["X Converter"] = converter(lateral_category, "Pixels", [0.0, dx_m, 0.0, 0.0])
        ds.attrs["Y Converter"] = converter(lateral_category, "Pixels", [0.0, dy_m, 0.0, 0.0])
        ds.attrs["Z Converter"] = converter(z_category, unit, [0.0, 632.8e-9, 0.5, 1.0])
        ds.attrs["Wavelength"] = np.array([632.8e-9])
        ds.attrs["Interferometric Scale Factor"] = np.array([0.5])
        ds.attrs["Obliquity Factor"] = np.array([1.0])
        group = h5.create_group(f"Attributes/{surface}")
        group.attrs["Data Context.Data Attributes.Resolution:Value"] = np.array([dx_m])


def write_plux(path, z_um, dx_um, dy_um, *, stated_shape=None):
    """A Sensofar .plux file after SurfaceTopography's PLUX.py (tested there on an S neox
    file): a ZIP of ``index.xml`` (GENERAL: IMAGE_SIZE_X/Y, FOV_X/Y the spacing in
    micrometres, DATE; INFO items; LAYER_0: FILENAME_Z), ``recipe.txt`` and the layer's
    float32 heights in micrometres, row by row, NaN where not measured. ``stated_shape``:
    the (rows, columns) index.xml states, if not the heights' own."""
    import zipfile

    z = np.asarray(z_um, "<f4")
    ny, nx = stated_shape or z.shape
    index = (f"<xml><GENERAL><DATE>2026-12-01T12:00:00</DATE><IMAGE_SIZE_X>{nx}</IMAGE_SIZE_X>"
             f"<IMAGE_SIZE_Y>{ny}</IMAGE_SIZE_Y><FOV_X>{dx_um!r}</FOV_X><FOV_Y>{dy_um!r}</FOV_Y>"
             "</GENERAL><INFO><ITEM_0><NAME>Device</NAME><VALUE>S neox</VALUE></ITEM_0></INFO>"
             "<LAYER_0><FILENAME_Z>LAYER_0.raw</FILENAME_Z></LAYER_0></xml>")
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("index.xml", index)
        archive.writestr("recipe.txt", "<xml><RECIPE>pmdsim test</RECIPE></xml>")
        archive.writestr("LAYER_0.raw", z.tobytes())
