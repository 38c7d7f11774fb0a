build-san/obj/tests/unit/test_proto.o: tests/unit/test_proto.c \
 common/proto.h common/blob.h common/tile.h common/imgio.h common/scene.h \
 common/vec.h
common/proto.h:
common/blob.h:
common/tile.h:
common/imgio.h:
common/scene.h:
common/vec.h:
