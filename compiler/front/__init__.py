"""Front end: scene text -> Scene model. XML reading (xmlsafe), parsing with includes and macros
(parse), the model (model), link resolution (links), data files and meshes (datafiles, meshes),
and writing a model back as .scn (writer)."""
