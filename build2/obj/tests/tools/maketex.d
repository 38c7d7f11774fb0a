build2/obj/tests/tools/maketex.o: tests/tools/maketex.c \
 common/image/imgio.h common/base/log.h common/image/mip.h \
 common/base/vec.h
common/image/imgio.h:
common/base/log.h:
common/image/mip.h:
common/base/vec.h:
