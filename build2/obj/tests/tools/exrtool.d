build2/obj/tests/tools/exrtool.o: tests/tools/exrtool.c \
 common/image/imgio.h common/base/log.h
common/image/imgio.h:
common/base/log.h:
